"""The capture of ``ecatsim bench --bringup`` (ecatsim/bench/capture.py): frames parsed from the
wire, requests paired with replies by index and direction, resends and unanswered frames
counted, the figures per phase, on synthetic time stamps."""

from __future__ import annotations

import struct

from ecatsim.bench.capture import (
    Frame,
    analyse,
    cycle_frames,
    first_wkc,
    parse,
    process_cycles,
)
from ecatsim.wire import datagram as dg

MS = 1_000_000


def req(t: int, idx: int, cmd: int = 8, ado: int = 0x0120, data: bytes = b"\x01\x00") -> Frame:
    body = struct.pack("<BBHHH", cmd, idx, 0, ado, len(data)) + b"\x00\x00" + data
    return Frame(t, False, idx, cmd, 0, ado, len(data), body)


def rep(t: int, idx: int) -> Frame:
    return Frame(t, True, idx, 8, 0, 0x0120, 2, b"")


def test_parse_tells_replies_by_the_source_mac_bit() -> None:
    raw = dg.ethernet_frame([dg.build(dg.Cmd.BWR, 0, 0x0600, bytes(256), idx=0x42)])
    f = parse(raw, 5)
    assert f is not None
    assert (f.t_ns, f.reply, f.idx, f.cmd, f.adp, f.ado, f.length) == (
        5,
        False,
        0x42,
        8,
        0,
        0x0600,
        256,
    )
    assert len(f.body) == 10 + 48
    back = bytearray(raw)
    back[6] |= 0x02
    r = parse(bytes(back), 9)
    assert r is not None and r.reply and r.idx == 0x42
    assert parse(b"\x00" * 12 + b"\x08\x00" + bytes(40), 1) is None  # IPv4: not EtherCAT


def test_pairs_by_index_counts_resends_and_unanswered() -> None:
    frames = [
        req(0, 1),
        req(10_000, 2, cmd=7, ado=0x0130, data=b"\x00\x00"),
        rep(30_000, 2),  # 20 us
        rep(400_000, 1),  # 400 us
        req(1 * MS, 3, ado=0x0600, data=bytes(16)),
        req(3 * MS, 3, ado=0x0600, data=bytes(16)),  # the same request again: a resend
        rep(int(3.5 * MS), 3),  # 2.5 ms after the first copy
        rep(int(3.6 * MS), 3),  # the resend's reply: no request waits for it
        req(5 * MS, 4),  # never answered
        req(6 * MS, 5, data=b"\x02\x00"),
        req(7 * MS, 5, data=b"\x04\x00"),  # the index again, other data: 5's first unanswered
        rep(int(7.5 * MS), 5),  # 500 us
    ]
    a = analyse(frames)
    assert a["frames"] == 4
    assert (a["p50_us"], a["max_us"]) == (400.0, 2500.0)
    assert (a["over_1ms"], a["over_2ms"]) == (1, 1)
    assert (a["resends"], a["unanswered"], a["extra_replies"]) == (1, 2, 1)
    assert a["resent"] == [{"cmd": "BWR", "adp": "0x0000", "ado": "0x0600", "length": 16,
                            "after_us": 2000.0}]  # fmt: skip
    assert a["slowest"][0] == {"cmd": "BWR", "adp": "0x0000", "ado": "0x0600", "length": 16,
                               "us": 2500.0}  # fmt: skip
    assert [s["us"] for s in a["slowest"]] == [2500.0, 500.0, 400.0, 20.0]


def test_phases_take_the_requests_sent_in_them() -> None:
    frames = [req(0, 1), rep(100_000, 1), req(2 * MS, 2), rep(int(3.2 * MS), 2), req(4 * MS, 3),
              rep(int(4.01 * MS), 3)]  # fmt: skip
    a = analyse(frames, [(0, "config_init"), (int(1.5 * MS), "op")])
    assert a["phases"]["config_init"]["frames"] == 1
    assert a["phases"]["config_init"]["max_us"] == 100.0
    op = a["phases"]["op"]
    assert (op["frames"], op["max_us"], op["over_1ms"], op["p50_us"]) == (2, 1200.0, 1, 10.0)


def test_p999_is_nearest_rank() -> None:
    frames = []
    for i in range(2000):
        frames += [req(i * MS, i & 0xFF), rep(i * MS + (i + 1) * 1000, i & 0xFF)]
    a = analyse(frames)
    assert (a["frames"], a["p999_us"], a["max_us"], a["over_1ms"]) == (2000, 1998.0, 2000.0, 1000)


def test_the_same_request_much_later_is_a_new_one() -> None:
    """A master's cyclic frames repeat while its outputs do not change: the same index and
    datagram 30 ms later is a new request (the first one was not answered)."""
    a = analyse([req(0, 9), req(30 * MS, 9), rep(30 * MS + 50_000, 9)])
    assert (a["frames"], a["max_us"], a["resends"], a["unanswered"]) == (1, 50.0, 0, 1)


def test_the_first_datagrams_wkc_is_read_from_the_whole_frame() -> None:
    lrw = dg.build_logical(dg.Cmd.LRW, 0x100, bytes(1400), idx=7, wkc=141)
    dc = dg.build(dg.Cmd.FRMW, 1, 0x0910, bytes(8), idx=7)
    raw = dg.ethernet_frame([lrw, dg.build(dg.Cmd.NOP, 0, 0, b"")])
    assert first_wkc(raw) == 141
    assert first_wkc(dg.ethernet_frame([lrw, dc], vlan=5)) == 141  # behind an 802.1Q tag
    assert first_wkc(raw[:200]) == -1  # cut short before the WKC
    assert first_wkc(b"\x00" * 12 + b"\x08\x00" + bytes(40)) == -1  # not EtherCAT
    f = parse(raw, 3)
    assert f is not None and (f.wkc, f.length, len(f.body)) == (141, 1400, 10 + 48)
    g = parse(raw[:80], 3, True, 141)  # the capture kept the WKC, then cut the frame
    assert g is not None and (g.wkc, g.reply, g.adp, g.ado) == (141, True, 0x100, 0)


def lrw(t: int, idx: int, lad: int, reply: bool = False, wkc: int = 0) -> Frame:
    return Frame(t, reply, idx, 12, lad & 0xFFFF, lad >> 16, 1400, b"", wkc)


def test_cycles_are_summed_off_the_wire_lost_and_late_frames_add_nothing() -> None:
    """A cycle is the frames from the one to the lowest logical address on; its WKC is
    the sum of the WKCs that came back in time (3 ms here), as SOEM sums them."""
    frames = [
        lrw(0, 1, 0x0), lrw(10_000, 2, 0x5C0),  # sent before the window: not counted
        lrw(1 * MS, 3, 0x0), lrw(1 * MS + 10_000, 4, 0x5C0),
        lrw(1 * MS + 90_000, 3, 0x0, True, 141), lrw(1 * MS + 95_000, 4, 0x5C0, True, 15),
        lrw(2 * MS, 5, 0x0), lrw(2 * MS + 10_000, 6, 0x5C0),
        lrw(2 * MS + 90_000, 5, 0x0, True, 141),  # 6: never answered
        lrw(3 * MS, 7, 0x0), lrw(3 * MS + 10_000, 8, 0x5C0),
        lrw(3 * MS + 90_000, 7, 0x0, True, 141), lrw(7 * MS, 8, 0x5C0, True, 15),  # 8: late
        lrw(4 * MS, 9, 0x0), lrw(4 * MS + 10_000, 10, 0x5C0),
        lrw(4 * MS + 90_000, 9, 0x0, True, 140), lrw(4 * MS + 95_000, 10, 0x5C0, True, 15),
        lrw(5 * MS, 11, 0x0), lrw(5 * MS + 90_000, 11, 0x0, True, 141),  # sent after the end
    ]  # fmt: skip
    c = process_cycles(frames, 500_000, 5 * MS, 156, 3 * MS)
    assert (c["cycles"], c["frames"], c["lost"], c["late"]) == (4, 8, 2, 1)
    assert (c["wkc_errors"], c["wkc_error_seen"], c["expected_wkc"]) == (3, [141, 141, 155], 156)


def test_a_cycles_frames_are_timed_each_by_its_logical_address() -> None:
    """Each frame of a cycle by its place (its logical address), in address order: the
    second frame of each cycle waits behind the first; a stray frame and the frames sent
    outside the window are left out."""
    frames = [lrw(0, 1, 0x0), lrw(40_000, 1, 0x0, True)]  # before the window
    for k in range(1, 5):
        t = k * MS
        frames += [
            lrw(t, 2 * k, 0x0), lrw(t + 5_000, 2 * k + 1, 0x5C0),
            lrw(t + 100_000 + k * 1000, 2 * k, 0x0, True),
            lrw(t + 300_000 + k * 1000, 2 * k + 1, 0x5C0, True),
        ]  # fmt: skip
    frames += [lrw(5 * MS, 20, 0x900), lrw(5 * MS + 50_000, 20, 0x900, True)]  # stray
    got = cycle_frames(frames, 500_000, 6 * MS)
    assert got == [
        {"cmd": "LRW", "logical": "0x00000000", "frames": 4, "p50_us": 102.0,
         "p999_us": 104.0, "max_us": 104.0},
        {"cmd": "LRW", "logical": "0x000005C0", "frames": 4, "p50_us": 297.0,
         "p999_us": 299.0, "max_us": 299.0},
    ]  # fmt: skip
    assert cycle_frames(frames, 7 * MS, 8 * MS) == []
