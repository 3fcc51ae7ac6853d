"""Mutated frames through the in-process frame path: no exception escapes, error counters
count what an ESC counts, memory stays bounded, and the segment still reaches OP.

Ref: TMC8460 §5.35 (processing unit error counter); ETG.1000.4 §5.3/5.4.
"""

from __future__ import annotations

import random
import struct
import tracemalloc

from ecatsim.wire import datagram as dg
from tests.perf.hotpath import configure_to_op, op_segment
from tests.support.tinymaster import TinyMaster

SEED_FRAMES = [
    dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0000, b"\x00\x00")]),
    dg.ethernet_frame(
        [
            dg.build(dg.Cmd.APRD, 0, 0x0130, b"\x00\x00", more=True),
            dg.build(dg.Cmd.FPWR, 0x1000, 0x0120, b"\x02\x00"),
        ]
    ),
    dg.ethernet_frame(
        [
            dg.build_logical(dg.Cmd.LRW, 0, bytes(58), more=True),
            dg.build(dg.Cmd.FPRD, 0x1000, 0x0130, b"\x00\x00"),
        ]
    ),
    dg.ethernet_frame([dg.build(dg.Cmd.FPWR, 0x1000, 0x0502, b"\x00\x01\x08\x00\x00\x00")]),
    dg.ethernet_frame([dg.build(dg.Cmd.ARMW, 0, 0x0910, bytes(8))]),
]


def mutate(rng: random.Random, frame: bytes) -> bytes:
    f = bytearray(frame)
    k = rng.randrange(7)
    if k == 0:
        return bytes(f[: rng.randrange(0, len(f))])  # truncate
    if k == 1:
        return bytes(f + rng.randbytes(rng.randrange(1, 64)))  # extend
    if k == 2:
        for _ in range(rng.randrange(1, 8)):
            i = rng.randrange(14, len(f))
            f[i] ^= 1 << rng.randrange(8)  # flip bits
        return bytes(f)
    if k == 3:
        struct.pack_into("<H", f, 14, rng.randrange(0x10000))  # bad EtherCAT header
        return bytes(f)
    if k == 4:
        f[16] = rng.randrange(256)  # unknown command
        return bytes(f)
    if k == 5:
        struct.pack_into("<H", f, 22, rng.randrange(0x10000))  # length/flags past the end
        return bytes(f)
    i = rng.randrange(16, len(f))
    f[i:] = rng.randbytes(len(f) - i)  # random tail
    return bytes(f)


def test_100k_mutated_frames(count: int = 100_000) -> None:
    m, _frame, _n = op_segment(2)
    seg = m.seg
    rng = random.Random(20261122)
    buf = bytearray(2048)
    tracemalloc.start()
    before = None
    for i in range(count):
        f = mutate(rng, SEED_FRAMES[i % len(SEED_FRAMES)])
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
    # forwarded errors (the seed is fixed, so this run is reproducible)
    assert seg.escs[0].mem[0x030C] == 0xFF
    assert seg.escs[1].mem[0x0308] == 0xFF
    # the segment still works: a master configures it again and reaches OP
    t = TinyMaster(seg)
    configure_to_op(t, 2)
    assert t.brd(0x0130, 2).data == b"\x08\x00"
    assert t.brd(0x0130, 2).wkc == 2
