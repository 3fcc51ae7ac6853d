"""The compiled DC time loops (decision P11) against the Python reference: two segments in
lockstep, one serving the writers of each FRMW of 0x0910 through ecatsim/esc/_dcloop.c and
one through Esc.ecat_write, compared after every frame: replies, every byte of ESC memory,
each DC unit's state, the write range the hooks saw and the timers flag.

The slaves drift (one beyond the rate clamp), have propagation delays (0x0928), their own
offsets (0x0920) and speed-counter starts (0x0930), and the system time crosses a 2^32
boundary while 4-byte FRMWs run (the comparison modulo 2^32). Ref: TMC8460 §5.50.2
Tables 95-101; ETG.1000.4 Table 12 (FRMW); docs/decisions.md P7, P11."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from ecatsim.build import build_segment
from ecatsim.clock import ManualClock
from ecatsim.config import SegmentConfig, SlaveConfig
from ecatsim.esc import dc, regs
from ecatsim.esc.core import Esc
from ecatsim.segment import Segment
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster, decode

_dcloop = pytest.importorskip("ecatsim.esc._dcloop", reason="the C extension was not built")

DRIFTS = (0.0, 40.0, -75.0, 5000.0)  # ppm; 5000 needs more than the 1000 ppm rate clamp
DELAYS = (0, 120, 370, 610)  # ns, 0x0928
STARTS = (0x1000, 0x0400, 0x2800, 0x0800)  # 0x0930
STATION = 0x1000
MS = 1_000_000


def bench(compiled: bool) -> tuple[Segment, ManualClock, TinyMaster]:
    clock = ManualClock(1_000_000_000)
    slaves = (
        SlaveConfig(device="echo", serial=i + 1, dc_drift_ppm=d) for i, d in enumerate(DRIFTS)
    )
    cfg = SegmentConfig(tuple(slaves))
    seg = build_segment(cfg, clock)
    seg.compiled = compiled
    t = TinyMaster(seg)
    for i in range(len(DRIFTS)):
        t.apwr(i, regs.STATION_ADDRESS, struct.pack("<H", STATION + i))
        t.apwr(i, regs.DC_SYSTEM_TIME_DELAY, struct.pack("<I", DELAYS[i]))
        t.apwr(i, regs.DC_SPEED_COUNTER_START, struct.pack("<H", STARTS[i]))
        # each system time 40 ms before a 2^32 boundary, give or take the slave's own
        local = struct.unpack("<Q", t.aprd(i, regs.DC_SYSTEM_TIME, 8).data)[0]
        offset = (7 << 32) - 40 * MS - local + 3_000 * i
        t.apwr(i, regs.DC_SYSTEM_TIME_OFFSET, struct.pack("<Q", offset & (2**64 - 1)))
    seg.reply_first = True  # the writers' loops wait for after_reply, as in the daemon
    return seg, clock, t


def state(seg: Segment) -> dict[str, Any]:
    out: dict[str, Any] = {"timers": seg.ctx.timers_dirty, "pending": seg._dc_pending}
    for esc in seg.escs:
        u = esc.dc
        out[f"mem{esc.position}"] = bytes(esc.mem)
        out[f"dc{esc.position}"] = (u.local_ref, u.t_ref, u.rate_ppb, u.spd, u.moved_ns)
        out[f"wr{esc.position}"] = (esc.wr_s, esc.wr_e)
    return out


def frmw(adp: int, n: int) -> bytes:
    return dg.build(dg.Cmd.FRMW, adp, regs.DC_SYSTEM_TIME, bytes(n))


def test_constants_agree_with_the_python_model() -> None:
    assert _dcloop.MOVE_NS == dc.MOVE_NS
    assert _dcloop.DC_SYSTEM_TIME == regs.DC_SYSTEM_TIME
    assert _dcloop.DC_SYSTEM_TIME_OFFSET == regs.DC_SYSTEM_TIME_OFFSET
    assert _dcloop.DC_SYSTEM_TIME_DELAY == regs.DC_SYSTEM_TIME_DELAY
    assert _dcloop.DC_SYSTEM_TIME_DIFF == regs.DC_SYSTEM_TIME_DIFF
    assert _dcloop.DC_SPEED_COUNTER_START == regs.DC_SPEED_COUNTER_START
    assert _dcloop.DC_SPEED_COUNTER_DIFF == regs.DC_SPEED_COUNTER_DIFF


def test_time_loops_match_the_python_writes() -> None:
    a, clock_a, ta = bench(True)
    b, clock_b, tb = bench(False)
    assert state(a) == state(b)
    served = 0
    clamped = 0
    for k in range(600):
        # slave 0 reads (the wrap), then sometimes slave 2 (the slaves before it write the
        # master's data, zeros), at the end sometimes nobody (0x7777: every slave writes)
        ref = 0 if k < 200 else 0x7777 if k >= 560 and k % 8 == 7 else (0, 0, 0, 2)[k % 4]
        n = 4 if 20 <= k < 120 else 8  # 4 bytes across the 2^32 boundary (k = 40)
        step = MS + (k * 7919) % 3000 - 1500
        clock_a.advance(step)
        clock_b.advance(step)
        ra = ta.frame([frmw(STATION + ref if ref < 4 else ref, n)], service=False)
        rb = tb.frame([frmw(STATION + ref if ref < 4 else ref, n)], service=False)
        assert ra == rb, k
        assert a._dc_pending == n
        assert _dcloop.time_loops(a, Esc._ew_dc_system_time) is True
        served += 1
        b.after_reply()
        assert state(a) == state(b), k
        clamped += abs(a.escs[3].dc.rate_ppb) == 1e6
    assert served == 600
    # the loops did their work: the drifting clocks were corrected, the one beyond the
    # rate clamp hit it
    assert clamped > 0
    assert all(esc.dc.rate_ppb != 0.0 for esc in a.escs[1:])


def test_an_sm_window_over_the_register_declines_and_changes_nothing() -> None:
    a, clock, t = bench(True)
    clock.advance(MS)
    t.frame([frmw(STATION, 8)], service=False)
    before = state(a)
    # SM0 over 0x0910 on slave 2 (nonsense, but the ESC allows it): its write goes to the SM
    esc = a.escs[2]
    windows = esc.sm_windows
    esc.sm_windows = ((0x0900, 0x0920, esc.sm[0]),)
    assert _dcloop.time_loops(a, Esc._ew_dc_system_time) is False
    assert state(a) == before
    # a hook other than the plain register's declines too
    esc.sm_windows = windows
    assert _dcloop.time_loops(a, Esc._ew_dc_system_time_offset) is False
    assert state(a) == before
    assert _dcloop.time_loops(a, Esc._ew_dc_system_time) is True
    assert a._dc_pending == 0
    assert decode(t.last_frame, 14)[0].wkc == 4
