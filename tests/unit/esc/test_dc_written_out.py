"""The DC unit's per-cycle functions with their helpers written out (decision P76) give
what the helpers give: after random sequences of FRMW writes of 0x0910 (4 and 8 bytes,
near and far), offset, delay and filter writes, drift and SYNC0 pulses, every register,
the clock and the SYNC0 deadline are the values the unchanged methods (``local_time``,
``system_time``, ``_host_time``, ``_set_rate``, ``_speed_counter_diff``) compute.

Ref: TMC8460 §5.50.2 Tables 95-101 (time loop), §5.50.4 Tables 105-112 (SYNC0).
"""

from __future__ import annotations

import random

import pytest

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.regs import (
    DC_ACTIVATION,
    DC_SPEED_COUNTER_DIFF,
    DC_SPEED_COUNTER_START,
    DC_START_TIME,
    DC_SYNC0_CYCLE,
    DC_SYSTEM_TIME,
    DC_SYSTEM_TIME_DELAY,
    DC_SYSTEM_TIME_DIFF,
    DC_SYSTEM_TIME_OFFSET,
)

MASK64 = (1 << 64) - 1


def u(m: bytearray, a: int, n: int) -> int:
    return int.from_bytes(m[a : a + n], "little")


def signed(x: int) -> int:
    return x - (1 << 64) if x >= 1 << 63 else x


def expected_write(esc: Esc, t_frame: int, value: int, nbytes: int) -> dict[str, object]:
    """The time loop's result by the unchanged methods (TMC8460 Tables 95, 98, 101)."""
    dc = esc.dc
    m = esc.mem
    t = dc.arrival_ns(t_frame)
    delay = u(m, DC_SYSTEM_TIME_DELAY, 4)
    offset = dc.offset()
    local_now = dc.local_time(t)
    local = (local_now + offset - delay) & MASK64
    if nbytes < 8:
        diff = ((local - value + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)
    else:
        diff = signed((local - value) & MASK64)
    start = u(m, DC_SPEED_COUNTER_START, 2) & 0x7FFF
    gain = 1.0 / max(2.0, start / 0x400)
    rate = dc.rate_ppb
    if abs(diff) > 1_000_000:
        step = diff
    else:
        step = int(diff * gain)
        rate = max(-1e6, min(1e6, dc.rate_ppb - diff * gain * 5.0))
    local_ref = (local_now - step) & MASK64
    lim = max(0, start - 0x7F)
    x = max(-lim, min(lim, int(rate * 5e-9 * (start + 2) * (start + 2))))
    return {
        "t_ref": t,
        "local_ref": local_ref,
        "rate": rate,
        "spd": 1.0 + dc.drift_ppm * 1e-6 + rate * 1e-9,
        "diff_reg": min(abs(diff), 0x7FFFFFFF) | ((1 << 31) if diff < 0 else 0),
        "speed_diff": x & 0xFFFF,
        "time_reg": (local_ref + offset) & MASK64,
    }


def expected_next_sync0(esc: Esc, now: int) -> int:
    """The next SYNC0 time after a pulse at ``now`` (Tables 106-108: overdue pulses skipped)."""
    dc = esc.dc
    cycle = u(esc.mem, DC_SYNC0_CYCLE, 4)
    n0 = (dc.sync0_at + cycle) & MASK64
    behind = signed((dc.system_time(now) - n0) & MASK64)
    if behind >= cycle:
        n0 = (n0 + (behind // cycle) * cycle) & MASK64
    return n0


@pytest.mark.parametrize("seed", range(10))
def test_the_written_out_time_loop_and_sync0_match_the_methods(seed: int) -> None:
    rng = random.Random(seed)
    esc = Esc(
        0,
        FrameContext(),
        bytearray(b"\xff" * 256),
        dc_start_ns=rng.randrange(1 << 64),
        dc_drift_ppm=rng.uniform(-80.0, 80.0),
    )
    dc = esc.dc
    m = esc.mem
    m[DC_SYSTEM_TIME_OFFSET : DC_SYSTEM_TIME_OFFSET + 8] = rng.randrange(1 << 64).to_bytes(
        8, "little"
    )
    m[DC_SPEED_COUNTER_START : DC_SPEED_COUNTER_START + 2] = (0x1000).to_bytes(2, "little")
    cycle = rng.choice([125_000, 1_000_000, 999_983])
    m[DC_SYNC0_CYCLE : DC_SYNC0_CYCLE + 4] = cycle.to_bytes(4, "little")
    m[DC_ACTIVATION] = 0x03
    t = rng.randrange(1 << 40)
    dc.next_sync0 = dc.system_time(t) + cycle
    for step in range(400):
        t += rng.choice([cycle, cycle // 2, 3 * cycle, 17])
        r = rng.random()
        if r < 0.03:
            a = rng.choice([DC_SYSTEM_TIME_OFFSET, DC_SYSTEM_TIME_DELAY, DC_SPEED_COUNTER_START])
            m[a : a + 2] = rng.randrange(1 << 16).to_bytes(2, "little")
        # the reference clock's time as the FRMW brings it: near the local copy, or far
        nbytes = rng.choice([4, 8])
        near = (dc.system_time(dc.arrival_ns(t)) - u(m, DC_SYSTEM_TIME_DELAY, 4)) & MASK64
        value = (near + rng.choice([0, 3, -40, 900, -25_000, 5_000_000, 1 << 40])) & MASK64
        data = value.to_bytes(8, "little")[:nbytes]
        esc.ctx.t_ns = t
        want = expected_write(esc, t, value & ((1 << 8 * nbytes) - 1), nbytes)
        assert esc.ecat_write_system_time(data) == 1
        assert dc.t_ref == want["t_ref"], step
        assert dc.local_ref == want["local_ref"], step
        assert dc.rate_ppb == want["rate"], step
        assert dc.spd == want["spd"], step
        assert u(m, DC_SYSTEM_TIME_DIFF, 4) == want["diff_reg"], step
        assert u(m, DC_SPEED_COUNTER_DIFF, 2) == want["speed_diff"], step
        assert u(m, DC_SYSTEM_TIME, 8) == want["time_reg"], step
        # the deadline, then its pulse
        d = dc.sync0_deadline_or(-7)
        assert d == dc._host_time(dc.sync0_at), step
        now = max(d, t) + rng.choice([0, 0, 1, cycle, 5 * cycle])
        nxt = expected_next_sync0(esc, now)
        dc.sync0_pulse(now)
        assert dc.sync0_at == nxt, step
        assert u(m, DC_START_TIME, 8) == nxt, step
    dc.next_sync0 = None
    assert dc.sync0_deadline_or(-7) == -7
