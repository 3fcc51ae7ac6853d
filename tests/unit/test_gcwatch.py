"""The daemon's ``stopped`` line counts the garbage collector's pauses while it served."""

from __future__ import annotations

import gc

from ecatsim.ethercat.gcwatch import GcPauses


def test_collections_are_counted_and_timed_only_while_watched() -> None:
    with GcPauses() as pauses:
        assert pauses in gc.callbacks
        gc.collect(0)
        gc.collect(1)
    assert pauses not in gc.callbacks
    assert pauses.count == 2
    assert 0 < pauses.max_ns < 10**9
    gc.collect(0)
    assert pauses.count == 2
