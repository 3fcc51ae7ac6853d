"""A logical datagram reaches only the ESCs whose FMMUs its range overlaps, in wire order
(ecatsim/ethercat/logical_index.py): the same replies, WKCs and memories as the walk
through every ESC with FMMUs, over random FMMU layouts (bit-granular, overlapping, reading,
writing, both) changed while frames run, and random LRD/LWR/LRW datagrams.

Ref: ETG.1000.4 §5.4.3 Table 12; TMC8460 §5.48; docs/decisions.md P99.
"""

from __future__ import annotations

import random
import struct

from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster, segment_of

N = 48
FMMU = struct.Struct("<IHBBHBBB3x")  # TMC8460 §5.48 Table 75


def fmmu(lstart: int, length: int, pstart: int, kind: int, sbit: int = 0, ebit: int = 7) -> bytes:
    return FMMU.pack(lstart, length, sbit, ebit, pstart, sbit, kind, 1)


def twins() -> tuple[TinyMaster, TinyMaster]:
    a, b = TinyMaster(segment_of(N)[0]), TinyMaster(segment_of(N)[0])
    b.seg.logical_index.on = False  # the reference: every ESC with FMMUs
    return a, b


def random_fmmus(rng: random.Random) -> bytes:
    """0-3 active FMMUs over the ESC's RAM, the rest cleared (16 bytes each, 8 FMMUs)."""
    regs = b""
    for _ in range(rng.choice((0, 1, 1, 2, 3))):
        length = rng.randint(1, 40)
        bits = rng.random() < 0.2
        sbit, ebit = (rng.randint(0, 7), rng.randint(0, 7)) if bits else (0, 7)
        regs += fmmu(
            rng.randrange(3000),
            length,
            rng.randrange(0x1000, 0x1F00),
            rng.choice((1, 2, 3)),
            sbit,
            ebit,
        )
    return regs.ljust(16 * 8, b"\x00")


def test_the_index_walks_as_every_esc_would() -> None:
    rng = random.Random(7)
    a, b = twins()
    assert len(a.seg.logical) == 0  # no FMMU yet
    layout = [random_fmmus(rng) for _ in range(N)]
    for pos in range(N):
        ram = bytes(rng.randrange(256) for _ in range(0x0F00))
        for m in (a, b):
            m.apwr(pos, 0x0600, layout[pos])
            m.apwr(pos, 0x1000, ram)
    assert len(a.seg.logical) >= 32  # INDEX_MIN: the lookup, not the plain walk
    for i in range(600):
        if i % 25 == 24:  # an FMMU layout changes: the index is built anew
            pos = rng.randrange(N)
            regs = random_fmmus(rng)
            for m in (a, b):
                m.apwr(pos, 0x0600, regs)
        dgs = []
        for k in range(rng.randint(1, 3)):
            cmd = rng.choice((dg.Cmd.LRD, dg.Cmd.LWR, dg.Cmd.LRW))
            lad = rng.randrange(3100) if rng.random() < 0.95 else 0
            n = rng.randint(1, 300) if lad else 3100
            data = bytes(rng.randrange(256) for _ in range(n))
            dgs.append(dg.build_logical(cmd, lad, data, idx=k, more=True))
        dgs[-1] = dgs[-1][:6] + bytes([dgs[-1][6], dgs[-1][7] & 0x7F]) + dgs[-1][8:]
        ra, rb = a.frame(dgs), b.frame(dgs)
        assert ra == rb, i
    for ea, eb in zip(a.seg.escs, b.seg.escs, strict=True):
        assert ea.mem == eb.mem
    # the index walked fewer ESCs than the reference, which walked every one each time
    assert 0 < a.seg.logical_index.visits < b.seg.logical_index.visits


def test_a_datagram_visits_only_the_escs_it_reaches() -> None:
    m = TinyMaster(segment_of(N)[0])
    for pos in range(N):  # 10 logical bytes each, in a row, read from RAM
        m.apwr(pos, 0x0600, fmmu(10 * pos, 10, 0x1000, 1))
        m.apwr(pos, 0x1000, bytes([pos]) * 10)
    idx = m.seg.logical_index
    before = idx.visits
    r = m.one(dg.build_logical(dg.Cmd.LRD, 105, bytes(20)))
    # slaves 10, 11 and 12 (bytes 100-109, 110-119, 120-129) each read once
    assert (r.wkc, r.data) == (3, bytes([10]) * 5 + bytes([11]) * 10 + bytes([12]) * 5)
    assert idx.visits - before == 3
    # the edges: the last byte of slave 10's FMMU; a datagram that ends where slave 10's
    # begins
    before = idx.visits
    r = m.one(dg.build_logical(dg.Cmd.LRD, 109, bytes(1)))
    assert (r.wkc, r.data, idx.visits - before) == (1, bytes([10]), 1)
    before = idx.visits
    r = m.one(dg.build_logical(dg.Cmd.LRD, 90, bytes(10)))
    assert (r.wkc, r.data, idx.visits - before) == (1, bytes([9]) * 10, 1)
    before = idx.visits
    r = m.one(dg.build_logical(dg.Cmd.LRD, 0, bytes(10 * N)))  # every slave: the plain walk
    assert (r.wkc, r.data) == (N, b"".join(bytes([p]) * 10 for p in range(N)))
    assert idx.visits - before == N
    before = idx.visits
    r = m.one(dg.build_logical(dg.Cmd.LRD, 10 * N, bytes(4)))  # beyond every FMMU
    assert (r.wkc, idx.visits - before) == (0, 0)
