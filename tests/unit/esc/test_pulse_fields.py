"""The SYNC0 pulse's time and the PDI interrupt lines kept as C fields (decisions P42,
P43): ``DcUnit.next_sync0`` reads and writes them as the int (or None) it was, and the
frame context's record of raised lines (a byte per position and their number) is the set
of positions it was, whatever order the lines of several ESCs rise and fall in, resets
included. Run against the compiled core and the pure-Python one alike.

Ref: TMC8460 §5.32, §5.33 (AL event request and mask, the PDI interrupt), §5.50.4
(SYNC0 generation).
"""

from __future__ import annotations

import random

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.regs import AL_EVENT_MASK, EV_SYNC0


def test_next_sync0_is_the_int_or_none_it_was() -> None:
    e = Esc(0, FrameContext(), bytearray(b"\xff" * 256))
    dc = e.dc
    assert dc.next_sync0 is None and not dc.sync0_on
    for v in (0, 1, 2**31, 2**63, 2**64 - 1):
        dc.next_sync0 = v
        assert dc.next_sync0 == v and type(dc.next_sync0) is int and dc.sync0_on
        assert dc.sync0_deadline() is not None
    dc.next_sync0 = None
    assert dc.next_sync0 is None and not dc.sync0_on
    assert dc.sync0_deadline() is None
    assert dc.sync0_deadline_or(-5) == -5
    assert not dc.sync0_pulse(10**9)  # nothing scheduled: no pulse


def test_the_raised_lines_are_the_set_of_positions() -> None:
    ctx = FrameContext()
    positions = (0, 1, 7, 64, 300)
    escs = [Esc(p, ctx, bytearray(b"\xff" * 256)) for p in positions]
    for e in escs:
        e.mem[AL_EVENT_MASK : AL_EVENT_MASK + 4] = EV_SYNC0.to_bytes(4, "little")
    rnd = random.Random(41)
    model: set[int] = set()
    for _ in range(2000):
        e = rnd.choice(escs)
        op = rnd.randrange(3)
        if op == 0:
            e.set_al_event(EV_SYNC0)
            model.add(e.position)
        elif op == 1:
            e.clr_al_event(EV_SYNC0)
            model.discard(e.position)
        else:
            e.power_on()  # a reset drops the line (the mask is cleared too)
            e.mem[AL_EVENT_MASK : AL_EVENT_MASK + 4] = EV_SYNC0.to_bytes(4, "little")
            model.discard(e.position)
        assert ctx.pending == model
        assert ctx.n_raised == len(model)
        assert all(x.irq_line == (x.position in model) for x in escs)
    assert isinstance(ctx.pending, set)
