"""The DC registers every cycle touches are reached by direct calls in the compiled core
(decisions P24-P26): each fast path must do what the register table's hook, called the
general way, does. Twin ESCs, one served by the fast path and one by the table's hook,
end with the same memory and the same clock.

Ref: TMC8460 §5.50.2 Table 95, §5.50.4 Table 108.
"""

from __future__ import annotations

import pytest

from ecatsim.esc.core import Esc, FrameContext, tables
from ecatsim.esc.dc import DcUnit
from ecatsim.esc.regs import DC_SYSTEM_TIME

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


def same(fast: Esc, slow: Esc) -> None:
    assert fast.mem == slow.mem
    assert fast.dc.local_ref == slow.dc.local_ref
    assert fast.dc.t_ref == slow.dc.t_ref
    assert fast.dc.spd == slow.dc.spd
    assert fast.al_event() == slow.al_event()
    assert fast.ctx.pending == slow.ctx.pending


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
