"""The bench master's csp motion (ecatsim/bench/master.py CspMotion): the enable sequence and
the cosine, byte for byte, for drives that enable in different cycles."""

from __future__ import annotations

import math

from ecatsim.bench.master import RX, TX, CspMotion


class FakeSlave:
    """A pysoem slave's process data: ``input`` bytes, ``output`` set by the master."""

    def __init__(self, position: int) -> None:
        self.input = TX.pack(0x0250, 8, position, 0, 0, 0)  # switch on disabled
        self.output = b""


class FakeMaster:
    def __init__(self, n: int) -> None:
        self.slaves = [FakeSlave(1000 * i - 7) for i in range(n)]


def answer(s: FakeSlave) -> None:
    """The drive's statusword after the controlword it was sent (CiA 402-2 Figure 5)."""
    cw = RX.unpack(s.output)[0]
    sw = {0x06: 0x0221, 0x07: 0x0233, 0x0F: 0x0237}[cw]
    s.input = TX.pack(sw, 8, TX.unpack(s.input)[2], 0, 0, 0)


def test_every_drive_is_enabled_then_follows_its_own_cosine_from_where_it_stood() -> None:
    m = FakeMaster(3)
    mo = CspMotion(m, 1000)
    sent: list[list[tuple[int, int, int, int]]] = []
    for cycle in range(12):
        mo.outputs()
        sent.append([RX.unpack(s.output) for s in m.slaves])
        for s in m.slaves[:2] if cycle < 5 else m.slaves:  # the last drive answers late
            answer(s)
    # the enable sequence: 6 until "ready to switch on", 7 until "switched on", then 15
    assert [row[0][0] for row in sent[:4]] == [0x06, 0x07, 0x0F, 0x0F]
    assert [row[2][0] for row in sent[:8]] == [0x06] * 6 + [0x07, 0x0F]

    # enabled (0x27): the position follows A (1 - cos(pi k dt)) / 2 from the start, k from 1
    def expected(start: int, k: int) -> int:
        return start + round(4096 * (1.0 - math.cos(math.pi * k * 1e-3)) / 2.0)

    assert [row[0][1] for row in sent[:3]] == [-7, -7, -7]
    assert [row[0][1] for row in sent[3:6]] == [expected(-7, k) for k in (1, 2, 3)]
    assert [row[1][1] for row in sent[3:6]] == [expected(993, k) for k in (1, 2, 3)]
    # the late drive's cosine starts at k = 1 in its own first enabled cycle (cycle 8)
    assert [row[2][1] for row in sent[7:12]] == [1993] + [expected(1993, k) for k in (1, 2, 3, 4)]
    assert sent[11][0] == (0x0F, expected(-7, 9), 0, 0)
