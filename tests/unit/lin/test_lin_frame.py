"""LIN 1.3 framing on the pty: PID parity, classic checksum, lengths, the parser.

Ref: TMC211 §6.7 Table 14, §6.9; the reserved identifiers' bytes from §6.11 tables.
"""

from __future__ import annotations

from ecatsim.lin.frame import (
    LinError,
    Parser,
    classic_checksum,
    data_length,
    frame,
    header,
    protect,
    response,
    unprotect,
)


class Recorder:
    """A FrameHandler that answers identifier 0x10 with two bytes."""

    def __init__(self) -> None:
        self.headers: list[int] = []
        self.frames: list[tuple[int, bytes]] = []
        self.errors: list[LinError] = []

    def on_header(self, ident: int, now_ns: int) -> bytes | None:
        self.headers.append(ident)
        return response(b"\x12\x34") if ident == 0x10 else None

    def on_frame(self, ident: int, data: bytes, now_ns: int) -> None:
        self.frames.append((ident, data))

    def on_error(self, error: LinError, now_ns: int) -> None:
        self.errors.append(error)


def test_pid_of_the_reserved_identifiers_as_the_sheet_prints_them() -> None:
    # §6.11.9: 0x3C is "0 0 1 1 1 1 0 0"; §6.11.1: 0x3D is "0 1 1 1 1 1 0 1"
    assert protect(0x3C) == 0x3C
    assert protect(0x3D) == 0x7D


def test_pid_parity_known_values() -> None:
    assert [protect(i) for i in (0x00, 0x01, 0x10, 0x20, 0x3F)] == [0x80, 0xC1, 0x50, 0x20, 0xBF]


def test_unprotect_rejects_every_wrong_parity() -> None:
    good = {protect(i) for i in range(64)}
    assert len(good) == 64
    for pid in range(256):
        assert (unprotect(pid) is not None) == (pid in good)
        if pid in good:
            assert protect(unprotect(pid) or 0) == pid


def test_classic_checksum() -> None:
    assert classic_checksum(bytes((0x4A, 0x55, 0x93, 0xE5))) == 0xE6  # carry wraps twice
    assert classic_checksum(b"\x00\x00") == 0xFF
    assert classic_checksum(b"\xff" * 8) == 0x00


def test_data_length_from_identifier_bits_5_4() -> None:
    assert [data_length(i) for i in (0x00, 0x1F, 0x20, 0x2F, 0x30, 0x3C, 0x3D)] == [
        2,
        2,
        4,
        4,
        8,
        8,
        8,
    ]


def test_master_frame_is_delivered_once_with_its_data() -> None:
    r = Recorder()
    p = Parser(r)
    out = p.feed(frame(0x3C, bytes(range(8))), 0)
    assert out == b""
    assert r.frames == [(0x3C, bytes(range(8)))]
    assert r.errors == []


def test_published_frame_is_answered_after_the_header() -> None:
    r = Recorder()
    p = Parser(r)
    assert p.feed(header(0x10), 0) == b"\x12\x34" + bytes((classic_checksum(b"\x12\x34"),))
    assert p.answered == 1


def test_bad_parity_is_a_header_error_and_the_next_frame_is_understood() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(bytes((0x00, 0x55, 0x3C ^ 0x40)) + bytes(9), 0)
    assert r.errors[0] == LinError.HEADER
    assert r.frames == []
    p.feed(frame(0x3C, bytes(8)), 100_000_000)
    assert r.frames == [(0x3C, bytes(8))]


def test_bad_sync_is_a_header_error() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(bytes((0x00, 0x54, 0x3C)), 0)
    assert r.errors[0] == LinError.HEADER
    assert p.errors["HEADER"] >= 1


def test_bad_checksum_is_a_data_error() -> None:
    r = Recorder()
    p = Parser(r)
    f = bytearray(frame(0x3C, bytes(8)))
    f[-1] ^= 1
    p.feed(bytes(f), 0)
    assert r.errors == [LinError.DATA]
    assert r.frames == []


def test_short_frame_times_out_as_a_timeout_error() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(frame(0x3C, bytes(8))[:7], 0)
    limit = p.frame_ns(0x3C)
    assert limit == int(1.4 * (34 + 90) * 1e9 / 19200)  # LIN 1.3 T_frame_max
    p.expire(limit - 1)
    assert r.errors == []
    p.expire(limit)
    assert r.errors == [LinError.TIMEOUT]


def test_late_byte_ends_the_old_frame_and_starts_a_new_one() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(frame(0x3C, bytes(8))[:5], 0)
    p.feed(frame(0x3C, b"\x01" * 8), 50_000_000)
    assert r.errors == [LinError.TIMEOUT]
    assert r.frames == [(0x3C, b"\x01" * 8)]


def test_header_nobody_answers_is_no_error() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(header(0x11), 0)
    p.expire(50_000_000)
    assert r.errors == []
    assert r.headers == [0x11]


def test_noise_between_frames_is_a_header_error_per_byte() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(b"\x13\x37", 0)
    assert r.errors == [LinError.HEADER, LinError.HEADER]
    assert p.noise == 2


def test_long_break_reads_as_several_zero_bytes() -> None:
    r = Recorder()
    p = Parser(r)
    p.feed(b"\x00\x00" + frame(0x3C, bytes(8)), 0)
    assert r.frames == [(0x3C, bytes(8))]
    assert r.errors == []


def test_parser_deadline_follows_the_frame_in_progress() -> None:
    r = Recorder()
    p = Parser(r, baud=9600)
    assert p.deadline_ns() is None
    p.feed(header(0x3C), 1000)
    assert p.deadline_ns() == 1000 + int(1.4 * 124 * 1e9 / 9600)
