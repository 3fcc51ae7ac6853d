"""What the way to SAFEOP and OP builds is moved out of the cyclic collector (decision P57),
so a full collection in the cycles does not walk it."""

from __future__ import annotations

import gc

from tests.perf.hotpath import configure_to_op
from tests.support.tinymaster import TinyMaster, segment_of


def test_the_transitions_to_safeop_and_op_freeze_what_the_collector_tracks() -> None:
    seg, clock = segment_of(1, device="tmc8670")
    m = TinyMaster(seg, clock)
    gc.unfreeze()
    try:
        assert gc.get_freeze_count() == 0
        configure_to_op(m, 1)
        assert seg.escs[0].mem[0x0130] & 0x0F == 0x08  # OP
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()  # the rest of the session collects as before
