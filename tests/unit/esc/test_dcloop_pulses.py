"""The compiled SYNC0 pulses (decision P12) against the Python reference: two segments in
lockstep, one firing its pulses through ecatsim/esc/_dcloop.c ``pulses`` and one through
Segment.sync_until's Python loop, compared after every step: every byte of ESC memory,
each DC unit's state, the PDI interrupts pending, the segment's next deadline, pulse hint,
pulse count and lateness, and what each firmware was asked to serve and when.

The slaves drift, have their own offsets and start times, one runs SYNC0 single shot,
two map SYNC0 to the AL event (0x0151 bit 3) and two do not, the master's FRMW moves the
clocks (sometimes far enough to mark the timers dirty), and the host stalls: a few cycles
(caught up pulse by pulse), and more than MAX_SYNC0_CATCHUP cycles (one pulse now, the
rest skipped). Ref: TMC8460 §5.50.4 Tables 105-112; §5.32; ETG.1000.6 §5.3; decisions
DC2, P12."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from ecatsim import segment as segment_mod
from ecatsim.build import build_segment
from ecatsim.clock import ManualClock
from ecatsim.config import SegmentConfig, SlaveConfig
from ecatsim.esc import regs
from ecatsim.esc.core import Esc
from ecatsim.esc.dc import DcUnit
from ecatsim.segment import Segment
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster

_dcloop = pytest.importorskip("ecatsim.esc._dcloop", reason="the C extension was not built")

DRIFTS = (0.0, 40.0, -75.0, 900.0)  # ppm
CYCLES = (1_000_000, 1_000_000, 0, 500_000)  # 0x09A0; slave 2 single shot
MAPPED = (True, False, True, False)  # 0x0151 bit 3: SYNC0 to AL event 0x0220.2
STATION = 0x1000
MS = 1_000_000


class Recorder:
    """Stands in front of a firmware: records each service(now) call, then serves."""

    def __init__(self, fw: Any, log: list[tuple[int, int]], position: int) -> None:
        self.fw = fw
        self.log = log
        self.position = position

    def service(self, now_ns: int) -> None:
        self.log.append((self.position, now_ns))
        self.fw.service(now_ns)

    def reset(self) -> None:
        self.fw.reset()


def bench(compiled: bool) -> tuple[Segment, ManualClock, TinyMaster, list[tuple[int, int]]]:
    clock = ManualClock(1_000_000_000)
    slaves = (
        SlaveConfig(device="echo", serial=i + 1, dc_drift_ppm=d) for i, d in enumerate(DRIFTS)
    )
    seg = build_segment(SegmentConfig(tuple(slaves)), clock)
    seg.compiled = compiled
    log: list[tuple[int, int]] = []
    seg.firmware = [Recorder(fw, log, i) for i, fw in enumerate(seg.firmware)]
    t = TinyMaster(seg)
    now = struct.unpack("<Q", t.aprd(0, regs.DC_SYSTEM_TIME, 8).data)[0]
    for i, esc in enumerate(seg.escs):
        t.apwr(i, regs.STATION_ADDRESS, struct.pack("<H", STATION + i))
        local = struct.unpack("<Q", t.aprd(i, regs.DC_SYSTEM_TIME, 8).data)[0]
        t.apwr(i, regs.DC_SYSTEM_TIME_OFFSET, struct.pack("<Q", (now - local) & (2**64 - 1)))
        # 0x0151 comes from the SII's PDI configuration (0x0E here): bit 3 set or cleared
        cfg = esc.mem[regs.SYNC_LATCH_CONFIG]
        esc.mem[regs.SYNC_LATCH_CONFIG] = cfg | 0x08 if MAPPED[i] else cfg & 0xF7
        t.apwr(i, regs.DC_SYNC0_CYCLE, struct.pack("<I", CYCLES[i]))
        start = now + 3 * MS + 37_000 * i
        t.apwr(i, regs.DC_START_TIME, struct.pack("<Q", start))
        t.apwr(i, regs.DC_ACTIVATION, b"\x03")
    return seg, clock, t, log


def state(seg: Segment, log: list[tuple[int, int]]) -> dict[str, Any]:
    out: dict[str, Any] = {
        "timers": seg.ctx.timers_dirty,
        "pending": sorted(seg.ctx.pending),
        "next": (seg._next_sync, seg._pulse_hint),
        "ticks": (seg.sync0_ticks, seg.sync0_late_ns),
        "served": list(log),
    }
    for esc in seg.escs:
        u = esc.dc
        out[f"mem{esc.position}"] = bytes(esc.mem)
        out[f"dc{esc.position}"] = (
            u.next_sync0,
            u.next_sync1,
            u.sync1_countdown,
            u.local_ref,
            u.t_ref,
            u.spd,
        )
    return out


def frmw() -> bytes:
    return dg.build(dg.Cmd.FRMW, STATION, regs.DC_SYSTEM_TIME, bytes(8))


def test_constants_agree_with_the_python_model() -> None:
    for name in ("MAX_SYNC0_CATCHUP", "PULSE_HINT_MARGIN_NS", "NO_DEADLINE"):
        assert getattr(_dcloop, name) == getattr(segment_mod, name), name
    for name in (
        "SYNC_LATCH_CONFIG",
        "DC_START_TIME",
        "DC_SYNC0_CYCLE",
        "DC_ACTIVATION",
        "DC_ACTIVATION_STATUS",
        "DC_SYNC0_STATUS",
        "AL_EVENT_REQUEST",
        "AL_EVENT_MASK",
        "EV_SYNC0",
    ):
        assert getattr(_dcloop, name) == getattr(regs, name), name


def test_pulses_match_the_python_loop() -> None:
    a, clock_a, ta, log_a = bench(True)
    b, clock_b, tb, log_b = bench(False)
    assert state(a, log_a) == state(b, log_b)
    served = declined = 0
    for k in range(400):
        # mostly a cycle and a bit, sometimes a short stall (a few pulses due at once) and
        # three of more than MAX_SYNC0_CATCHUP cycles
        step = 170_000 + (k * 7919) % 900_000
        if k % 37 == 5:
            step = 4 * MS + 123_456
        if k in (150, 300):
            step = 90 * MS
        if k == 220:  # the pulse fired at once is 1-2 cycles behind: one more is skipped
            step = 67 * MS + 400_000
        for clock in (clock_a, clock_b):
            clock.advance(step)
        t = clock_a.now_ns()
        if k % 3 == 0:  # the master's FRMW moves the clocks (and sometimes the deadlines)
            ra = ta.frame([frmw()], service=False)
            rb = tb.frame([frmw()], service=False)
            assert ra == rb, k
            a.after_reply()
            b.after_reply()
        if _dcloop.pulses(a, t, Esc, DcUnit):
            served += 1
        else:
            assert a.ctx.timers_dirty, k  # the only decline here: the list is stale
            declined += 1
            a.sync_until(t)
        b.sync_until(t)
        assert state(a, log_a) == state(b, log_b), k
    # the compiled path did the work, the Python loop only after the clocks moved far
    assert served > 300 and declined > 0
    # what was exercised: pulses served by the firmware of the mapped slaves only, the
    # single shot fired once, catch-up bursts and the skip after a long stall
    assert {p for p, _ in log_a} == {0, 2}
    assert [p for p, _ in log_a].count(2) == 1
    assert a.escs[2].dc.next_sync0 is None
    assert a.sync0_late_ns >= 89 * MS
    assert a.sync0_ticks > 400


def test_sync1_another_esc_type_or_dirty_timers_decline_and_change_nothing() -> None:
    a, clock, _master, log = bench(True)
    clock.advance(5 * MS)
    now = clock.now_ns()
    assert len(a.sync_escs) == 4  # the list made anew
    before = state(a, log)
    # SYNC1 enabled on one slave: the Python loop handles SYNC1
    a.escs[1].mem[regs.DC_ACTIVATION] |= 0x04
    assert _dcloop.pulses(a, now, Esc, DcUnit) is False
    a.escs[1].mem[regs.DC_ACTIVATION] &= 0xFB
    assert state(a, log) == before
    # a SYNC1 pulse scheduled
    a.escs[3].dc.next_sync1 = 5
    assert _dcloop.pulses(a, now, Esc, DcUnit) is False
    a.escs[3].dc.next_sync1 = None
    assert state(a, log) == before
    # an ESC class other than the one transcribed
    assert _dcloop.pulses(a, now, DcUnit, DcUnit) is False
    assert _dcloop.pulses(a, now, Esc, Esc) is False
    assert state(a, log) == before
    # the ESC list is stale
    a.ctx.timers_dirty = True
    assert _dcloop.pulses(a, now, Esc, DcUnit) is False
    assert len(a.sync_escs) == 4
    assert state(a, log) == before
    assert _dcloop.pulses(a, now, Esc, DcUnit) is True
    assert a.sync0_ticks > 0
    assert log and log[0][0] == 0
