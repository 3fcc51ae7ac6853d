"""100 000 telegrams of garbage and of well-formed random commands: the TMCL door answers
what it should, never fails, and its memory stays bounded.

Ref: TMCM-1311 TMCL firmware manual §4.1-4.2 (telegrams), §4.2.1 (status codes).
"""

from __future__ import annotations

import gc
import random

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.program import MEMORY_SIZE
from tests.unit.tmcl.conftest import Bench

FRAMES = 100_000


def _telegram(rng: random.Random) -> bytes:
    kind = rng.random()
    if kind < 0.3:  # any bytes at all
        return rng.randbytes(P.FRAME_LEN)
    op = rng.choice([*range(1, 40), *range(64, 72), *range(128, 140), rng.randrange(256)])
    if op == P.FACTORY_DEFAULTS and rng.random() < 0.9:
        op = P.GAP
    cmd = P.Command(op, rng.randrange(256), rng.choice([0, 0, 0, 1, 2, 3, 255]), 0)
    value = rng.choice([0, 1, -1, 1234, 2**31 - 1, -(2**31), rng.randrange(-(2**31), 2**31)])
    data = bytearray(
        P.encode_command(
            rng.choice([1, 1, 1, 2, 0]), P.Command(cmd.opcode, cmd.type, cmd.motor, value)
        )
    )
    if kind < 0.35:
        data[8] ^= 1 + rng.randrange(255)  # wrong checksum
    return bytes(data)


def test_100k_telegrams_never_fail_and_memory_stays_bounded() -> None:
    rng = random.Random(1311)
    bench = Bench()
    replies = 0
    half = 0
    for i in range(FRAMES):
        data = _telegram(rng)
        if rng.random() < 0.01:  # a short frame, then a pause: the receiver restarts
            bench.send(data[: rng.randrange(1, 9)])
            bench.clock.advance(30_000_000)
        before = len(bench.line.sent)
        bench.send(data)
        replies += len(bench.line.sent) > before
        bench.line.sent.clear()
        bench.clock.advance(100_000)
        st = bench.st
        if st.ascii is not None:
            bench.send(b"ABIN\r")  # 139 put the line into ASCII mode: back to binary
        if i % 1000 == 0:
            bench.door.service(bench.clock.now_ns())
            m = bench.m
            m.gp0[66] = 1  # keep the module at address 1 (SGP 66 moves it)
            m.gp0[75] = 0
            m.gp0[68] = 0
        if i == FRAMES // 2:
            gc.collect()
            half = len(gc.get_objects())
    gc.collect()
    end = len(gc.get_objects())
    m = bench.m
    assert replies > FRAMES // 3
    assert bench.door.frames >= FRAMES * 9 // 10  # the rest went to ASCII mode
    assert bench.door.bad_checksums > 1000
    assert m.errors > 1000
    assert len(m.program) == MEMORY_SIZE
    assert len(m.interp.stack) <= 8
    assert bench.st.framer.pending < P.FRAME_LEN
    assert len(bench.st.queue) < 64
    assert end - half < 1000, (half, end)  # no objects pile up
    # and it still answers like a module
    bench.st.ascii = None
    bench.st.framer.take()
    bench.clock.advance(30_000_000)
    m.interp.download = False
    m.gp0[73] = 0
    assert bench.cmd(P.SAP, 4, 0, 1000) == (P.OK, 1000)
    assert bench.cmd(P.GAP, 4) == (P.OK, 1000)
    bench.door.close()
