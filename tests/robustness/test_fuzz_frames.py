"""Mutated frames (from a recorded pysoem bring-up) through the in-process frame path: no
exception escapes, error counters count what an ESC counts, memory stays bounded, and the
segment still reaches OP. A longer run: tools/fuzz_frames.py.

Ref: TMC8460 §5.35 (processing unit error counter); ETG.1000.4 §5.3/5.4.
"""

from __future__ import annotations

import random
import tracemalloc

from tests.perf.hotpath import configure_to_op, op_segment
from tests.support.fuzz import mutate, seed_frames
from tests.support.tinymaster import TinyMaster


def test_100k_mutated_frames(count: int = 100_000) -> None:
    m, _frame, _n = op_segment(2)
    seg = m.seg
    rng = random.Random(20261122)
    seeds = seed_frames()
    assert len(seeds) > 200  # the recorded pysoem bring-up is there
    buf = bytearray(2048)
    tracemalloc.start()
    before = None
    for i in range(count):
        f = mutate(rng, seeds[i % len(seeds)])
        buf[: len(f)] = f
        if len(f) >= 16:
            seg.process(buf, 14, len(f))
        seg.service()
        if i == 10_000:
            before = tracemalloc.get_traced_memory()[0]
    after = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    assert before is not None and after - before < 2_000_000  # bounded
    assert seg.bad_frames > 10_000
    # the first ESC counts malformed frames, saturating at 0xFF; the second counts them as
    # forwarded errors while it is reachable (mutated DL control writes close ports, and
    # counter writes clear them: exact counts per frame are in tests/golden)
    assert seg.escs[0].mem[0x030C] == 0xFF
    assert 0 < seg.escs[1].mem[0x0308] <= 0xFF
    # the segment still works: a master configures it again and reaches OP
    t = TinyMaster(seg)
    configure_to_op(t, 2)
    assert t.brd(0x0130, 2).data == b"\x08\x00"
    assert t.brd(0x0130, 2).wkc == 2
