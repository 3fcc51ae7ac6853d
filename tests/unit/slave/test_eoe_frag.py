"""The EoE fragmenter and reassembler against hand-built fragments: offsets, sizes, the
last-fragment flag, frame numbers, time appended. Ref: ETG.1000.6 §5.7."""

from __future__ import annotations

import struct

import pytest

from ecatsim.slave.eoe_frag import Fragmenter, Reassembler
from ecatsim.wire.eoe import decode_header, fragment_header


def frag(
    number: int, offset: int, frame: int, last: bool, data: bytes, time: bool = False
) -> tuple[object, bytes]:
    hdr = fragment_header(
        fragment=number, offset=offset, frame=frame, last=last, time_appended=time
    )
    return decode_header(hdr), data


def feed(r: Reassembler, *frags: tuple[object, bytes]) -> list[bytes | None]:
    return [r.feed(h, d) for h, d in frags]  # type: ignore[arg-type]


FRAME = bytes(range(256)) * 6  # 1536 bytes


def test_header_words_exact() -> None:
    # fragment 2, offset 6 blocks, frame 9, last, time appended, port 0
    hdr = fragment_header(fragment=2, offset=6, frame=9, last=True, time_appended=True)
    assert hdr == struct.pack("<HH", 0x0300, 2 | (6 << 6) | (9 << 12))
    h = decode_header(hdr)
    assert (h.ftype, h.fragment, h.offset, h.frame, h.last, h.time_appended) == (
        0,
        2,
        6,
        9,
        True,
        True,
    )


def test_fragmenter_for_a_128_byte_sm1() -> None:
    # SM1 128: 122 bytes after the mailbox header, 118 after the EoE header -> 96 per fragment
    f = Fragmenter(FRAME[:1442], frame_no=3, room=118)
    out = []
    while not f.done:
        out.append(f.next())
    assert len(out) == 15  # 14 x 96, then the last 98 bytes (the last needs no 32-multiple)
    for i, b in enumerate(out):
        h = decode_header(b)
        data = b[4:]
        assert h.fragment == i and h.frame == 3 and h.ftype == 0
        assert h.last == (i == 14)
        if i == 0:
            assert h.offset == (1442 + 31) // 32 == 46  # whole size, rounded up
        else:
            assert h.offset == i * 96 // 32
        assert len(data) == (96 if i < 14 else 1442 - 14 * 96)
        assert len(data) + 4 <= 122
    assert b"".join(b[4:] for b in out) == FRAME[:1442]


def test_frame_that_fits_one_fragment() -> None:
    f = Fragmenter(FRAME[:60], frame_no=0, room=118)
    b = f.next()
    h = decode_header(b)
    assert f.done and h.last and h.fragment == 0 and h.offset == 2 and b[4:] == FRAME[:60]


def test_size_rounds_up_not_down() -> None:
    f = Fragmenter(FRAME[:65], frame_no=0, room=118)
    assert decode_header(f.next()).offset == 3  # 65 bytes: 3 blocks (2 would lose data)


def test_time_appended_on_the_last_fragment() -> None:
    # 116 bytes would fit 118 alone, but not with the 4-byte time stamp: two fragments
    f = Fragmenter(FRAME[:116], frame_no=1, room=118, timestamp=0x11223344)
    a, b = f.next(), f.next()
    ha, hb = decode_header(a), decode_header(b)
    assert f.done
    assert not ha.last and not ha.time_appended and len(a) - 4 == 96
    assert hb.last and hb.time_appended and b[4:] == FRAME[96:116] + struct.pack("<I", 0x11223344)
    r = Reassembler()
    assert feed(r, (ha, a[4:]), (hb, b[4:])) == [None, FRAME[:116]]


def test_too_large_or_too_small() -> None:
    with pytest.raises(ValueError):
        Fragmenter(bytes(2017), 0, 118)
    with pytest.raises(ValueError):
        Fragmenter(bytes(60), 0, 31)


def test_reassembles_the_masters_fragments() -> None:
    r = Reassembler()
    got = feed(
        r,
        frag(0, 4, 7, False, FRAME[:32]),
        frag(1, 1, 7, False, FRAME[32:96]),
        frag(2, 3, 7, True, FRAME[96:100]),
    )
    assert got == [None, None, FRAME[:100]]
    assert (r.counters.frames, r.counters.fragments, r.counters.dropped) == (1, 3, 0)


def test_lost_fragment_drops_the_frame_once_and_the_next_frame_passes() -> None:
    r = Reassembler()
    got = feed(
        r,
        frag(0, 4, 1, False, FRAME[:32]),
        frag(2, 2, 1, False, FRAME[64:96]),  # fragment 1 lost
        frag(3, 3, 1, True, FRAME[96:100]),
        frag(0, 2, 2, True, FRAME[:60]),
    )
    assert got == [None, None, None, FRAME[:60]]
    assert r.counters.dropped == 1 and r.counters.frames == 1


@pytest.mark.parametrize(
    "second",
    [
        frag(1, 1, 6, True, FRAME[32:40]),  # another frame number
        frag(1, 2, 5, True, FRAME[32:40]),  # wrong offset
        frag(2, 1, 5, True, FRAME[32:40]),  # fragment number skipped
    ],
)
def test_out_of_order_fragment_drops_the_frame(second: tuple[object, bytes]) -> None:
    r = Reassembler()
    assert feed(r, frag(0, 2, 5, False, FRAME[:32]), second) == [None, None]
    assert r.counters.dropped == 1 and r.counters.frames == 0


def test_new_frame_start_drops_the_unfinished_one() -> None:
    r = Reassembler()
    got = feed(r, frag(0, 4, 1, False, FRAME[:32]), frag(0, 2, 2, True, FRAME[:50]))
    assert got == [None, FRAME[:50]] and r.counters.dropped == 1


def test_data_beyond_the_announced_size_drops_the_frame() -> None:
    r = Reassembler()
    assert feed(r, frag(0, 1, 1, True, FRAME[:40])) == [None]  # 40 bytes, 1 block announced
    assert r.counters.dropped == 1


def test_continuation_without_a_start_counts_once() -> None:
    r = Reassembler()
    assert feed(r, frag(1, 1, 1, False, FRAME[:32]), frag(2, 2, 1, True, FRAME[:32])) == [
        None,
        None,
    ]
    assert r.counters.dropped == 1


def test_time_appended_is_stripped() -> None:
    r = Reassembler()
    got = feed(r, frag(0, 2, 4, True, FRAME[:60] + b"\x01\x02\x03\x04", time=True))
    assert got == [FRAME[:60]]


def test_frame_number_wraps_through_a_round_trip() -> None:
    r = Reassembler()
    for n in range(20):
        f = Fragmenter(FRAME[: 200 + n], frame_no=n, room=118)
        frags = []
        while not f.done:
            b = f.next()
            frags.append((decode_header(b), b[4:]))
        assert frags[0][0].frame == n & 0x0F
        assert feed(r, *frags)[-1] == FRAME[: 200 + n]
    assert r.counters.frames == 20 and r.counters.dropped == 0
