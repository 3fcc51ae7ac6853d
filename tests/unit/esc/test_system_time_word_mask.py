"""Esc.ecat_write_system_time merges the written bytes of 0x0910 into memory a 32-bit word
at a time under the ECAT write mask (decision P93): with any mask, twin ESCs, one written
through it and one through the register table (ecat_write of 0x0910 and its hook), feed
the DC time loop the same value and end in the same state.

Ref: TMC8460 §5.50.2 Table 95 (0x0910 write: the time loop's input).
"""

from __future__ import annotations

import random

import pytest

from ecatsim.esc.regs import DC_SYSTEM_TIME
from tests.unit.esc.test_dc_fast_paths import same, twins


@pytest.mark.parametrize("size", [4, 8])
def test_the_word_merge_is_the_byte_merge_under_any_mask(size: int) -> None:
    rng = random.Random(93 + size)
    fast, slow = twins()
    t = 1_000_000
    for step in range(300):
        # a mask per byte: all, none or some bits writable (each word keeps a writable bit,
        # so the table's hook runs for the register write)
        masks = [rng.choice([0xFF, 0xFF, 0x00, rng.randrange(256)]) for _ in range(8)]
        masks[0] |= 0x01
        masks[4] |= 0x01
        wmask = bytearray(fast.ecat_wmask)
        wmask[DC_SYSTEM_TIME : DC_SYSTEM_TIME + 8] = bytes(masks)
        for e in (fast, slow):
            e.ecat_wmask = bytes(wmask)
        t += rng.randrange(1, 2_000_000)
        for e in (fast, slow):
            e.ctx.t_ns = t
            e.ctx.timers_dirty = False
        now = int.from_bytes(fast.mem[DC_SYSTEM_TIME : DC_SYSTEM_TIME + 8], "little")
        delta = rng.choice([0, 5, -300, 70_000, -(10**7), 1 << 36, rng.randrange(1 << 64)])
        data = ((now + delta) % 2**64).to_bytes(8, "little")[:size]
        assert fast.ecat_write_system_time(data) == slow.ecat_write(DC_SYSTEM_TIME, data) == 1
        same(fast, slow)
        assert fast.dc.rate_ppb == slow.dc.rate_ppb, step
        assert (fast.wr_s, fast.wr_e) == (slow.wr_s, slow.wr_e)
        assert fast.ctx.timers_dirty == slow.ctx.timers_dirty
