"""The DC registers every cycle touches are reached by direct calls in the compiled core
(decisions P24-P26): each fast path must do what the register table's hook, called the
general way, does. Twin ESCs, one served by the fast path and one by the table's hook,
end with the same memory and the same clock.

Ref: TMC8460 §5.50.2 Table 95, §5.50.4 Table 108.
"""

from __future__ import annotations

import pytest

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.dc import DcUnit
from ecatsim.esc.pdi import Pdi
from ecatsim.esc.regs import (
    AL_EVENT_MASK,
    DC_PULSE_LENGTH,
    DC_SYNC0_STATUS,
    DC_SYNC1_STATUS,
    DC_SYSTEM_TIME,
    EV_SYNC0,
    EV_SYNC1,
)
from ecatsim.esc.units import tables

TIMES = (0, 1, 999_999, 10**9 + 7, 2**40 + 3)


def twins() -> tuple[Esc, Esc]:
    """Two ESCs in one state: a drifting clock with an offset."""
    escs = [
        Esc(0, FrameContext(), bytearray(b"\xff" * 256), dc_start_ns=123_456_789, dc_drift_ppm=d)
        for d in (37.5, 37.5)
    ]
    for e in escs:
        e.mem[0x0920:0x0928] = (0xFFFF_FFFF_0000_1234).to_bytes(8, "little")
    return escs[0], escs[1]


def pulsed_twins(ra: int, pulse_length: int) -> tuple[Esc, Esc]:
    """:func:`twins` with both SYNC pulses raised, unmasked and ``ra``'s status set."""
    fast, slow = twins()
    for e in (fast, slow):
        e.mem[DC_PULSE_LENGTH : DC_PULSE_LENGTH + 2] = pulse_length.to_bytes(2, "little")
        e.mem[AL_EVENT_MASK : AL_EVENT_MASK + 4] = (EV_SYNC0 | EV_SYNC1).to_bytes(4, "little")
        e.mem[ra] = 0x01
        e.set_al_event(EV_SYNC0 | EV_SYNC1)
    return fast, slow


def same(fast: Esc, slow: Esc) -> None:
    assert fast.mem == slow.mem
    assert fast.dc.local_ref == slow.dc.local_ref
    assert fast.dc.t_ref == slow.dc.t_ref
    assert fast.dc.spd == slow.dc.spd
    assert fast.al_event() == slow.al_event()
    assert fast.ctx.pending == slow.ctx.pending


@pytest.mark.parametrize(
    ("side", "hook"), [("ecat_r", DcUnit._er_system_time), ("ecat_w", DcUnit._ew_system_time)]
)
def test_every_byte_of_the_system_time_names_the_hook_the_fast_paths_call(
    side: str, hook: object
) -> None:
    """Esc.reg_read_hooks (ECAT read) and Esc.ecat_write_system_time (the writers' time
    loops) act as the table's hook of 0x0910 does, by direct calls in the compiled core:
    the table must name that same hook, with the whole register, for every byte of it."""
    t = tables()
    for a in range(DC_SYSTEM_TIME, DC_SYSTEM_TIME + 8):
        entry = getattr(t, side)[a]
        assert entry is not None
        assert entry[0] is hook
        assert entry[1:] == (DC_SYSTEM_TIME, 8)


@pytest.mark.parametrize("pdi", [False, True])
def test_the_system_time_read_is_the_tables_hook(pdi: bool) -> None:
    """Esc.reg_read_hooks refreshes (ECAT) or latches (PDI) 0x0910 inline: the same as the
    table's read hook of the register (DcUnit._er_system_time, _pr_system_time)."""
    t = tables()
    entry = (t.pdi_r if pdi else t.ecat_r)[DC_SYSTEM_TIME]
    assert entry is not None
    fn, ra, rs = entry
    assert fn is (DcUnit._pr_system_time if pdi else DcUnit._er_system_time)
    fast, slow = twins()
    for t_ns in TIMES:
        for e in (fast, slow):
            e.ctx.t_ns = t_ns
            e.ctx.pdi_ns = t_ns + 333
        fast.reg_read_hooks(DC_SYSTEM_TIME, DC_SYSTEM_TIME + 8, pdi)
        fn(slow.dc, ra, rs)
        same(fast, slow)
        assert fast.mem[DC_SYSTEM_TIME : DC_SYSTEM_TIME + 8] != bytes(8)


@pytest.mark.parametrize("pulse_length", [0, 1000])
@pytest.mark.parametrize("ra", [DC_SYNC0_STATUS, DC_SYNC1_STATUS])
def test_the_sync_status_read_is_the_tables_hook(ra: int, pulse_length: int) -> None:
    """Esc.reg_read_hooks serves the PDI read of 0x098E/0x098F (the firmware's acknowledge
    of every SYNC0 pulse) by direct calls: the same as the table's hook
    (DcUnit._pr_sync_status), in acknowledge mode (pulse length 0) and not."""
    t = tables()
    entry = t.pdi_r[ra]
    assert entry is not None
    fn, ra_, rs = entry
    assert fn is DcUnit._pr_sync_status
    assert (ra_, rs) == (ra, 1)
    assert t.ecat_r[ra] is None  # an ECAT read has no side effect
    fast, slow = pulsed_twins(ra, pulse_length)
    assert fast.ctx.pending == {0}
    fast.reg_read_hooks(ra, ra + 1, True)
    fn(slow.dc, ra, rs)
    same(fast, slow)
    assert fast.al_event() & (EV_SYNC0 | EV_SYNC1) == (
        EV_SYNC1 if ra == DC_SYNC0_STATUS else EV_SYNC0
    )
    assert fast.mem[ra] == (0x00 if pulse_length == 0 else 0x01)


@pytest.mark.parametrize("pulse_length", [0, 1000])
@pytest.mark.parametrize("ra", [DC_SYNC0_STATUS, DC_SYNC1_STATUS])
def test_the_firmwares_sync_acknowledge_is_the_tables_hook(ra: int, pulse_length: int) -> None:
    """Pdi.u8 of 0x098E/0x098F (the firmware's acknowledge of every pulse) calls the hook's
    body directly (decision P44): the same byte, memory, AL events and interrupt line as
    the general PDI read, which runs the table's hook (DcUnit._pr_sync_status)."""
    fast, slow = pulsed_twins(ra, pulse_length)
    byte = Pdi(fast).u8(ra)
    assert byte == Pdi(slow).read(ra, 1)[0] == (0x00 if pulse_length == 0 else 0x01)
    same(fast, slow)
    assert fast.irq_line == slow.irq_line
    assert fast.al_event() & (EV_SYNC0 | EV_SYNC1) == (
        EV_SYNC1 if ra == DC_SYNC0_STATUS else EV_SYNC0
    )
    assert fast.mem[ra] == (0x00 if pulse_length == 0 else 0x01)
    for e in (fast, slow):  # the other one too: the line drops
        e.clr_al_event(EV_SYNC0 | EV_SYNC1)
    assert fast.ctx.pending == slow.ctx.pending == set()
    assert not fast.irq_line


@pytest.mark.parametrize("size", [4, 8])
def test_the_time_loop_write_is_the_register_write(size: int) -> None:
    """Esc.ecat_write_system_time (a writer's DC time loop after the reply) does what
    ecat_write of 0x0910 through the table's write hook (DcUnit._ew_system_time) does:
    memory, clock, rate, the timers flag and the WKC increment, for small differences (the
    loop's correction) and large ones (the clock jumps)."""
    fast, slow = twins()
    for t_ns in TIMES:
        for e in (fast, slow):
            e.ctx.t_ns = t_ns
        fast.reg_read_hooks(DC_SYSTEM_TIME, DC_SYSTEM_TIME + 8, False)
        now = int.from_bytes(fast.mem[DC_SYSTEM_TIME : DC_SYSTEM_TIME + 8], "little")
        for delta in (0, 3, -250, 10**6, -(10**9)):
            for e in (fast, slow):
                e.ctx.timers_dirty = False
            data = ((now + delta) % 2**64).to_bytes(8, "little")[:size]
            assert fast.ecat_write_system_time(data) == slow.ecat_write(DC_SYSTEM_TIME, data) == 1
            same(fast, slow)
            assert fast.dc.rate_ppb == slow.dc.rate_ppb
            assert (fast.wr_s, fast.wr_e) == (slow.wr_s, slow.wr_e)
            assert fast.ctx.timers_dirty == slow.ctx.timers_dirty
