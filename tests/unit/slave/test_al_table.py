"""Every (state, request) pair of the AL state machine, through the firmware.

Ref: ETG.1000.6 §6.4.1 Table 9; AL status codes ETG.1000.6 Table 11.
"""

from __future__ import annotations

import struct

import pytest

from ecatsim.slave.al import AlState
from tests.support.tinymaster import TinyMaster, segment_of

STATES = [AlState.INIT, AlState.PREOP, AlState.BOOT, AlState.SAFEOP, AlState.OP]
#: (from, request) -> (resulting AL status, AL status code)
EXPECTED: dict[tuple[AlState, AlState], tuple[int, int]] = {
    (AlState.INIT, AlState.INIT): (0x01, 0),
    (AlState.INIT, AlState.PREOP): (0x02, 0),
    (AlState.INIT, AlState.BOOT): (0x03, 0),
    (AlState.INIT, AlState.SAFEOP): (0x11, 0x0011),
    (AlState.INIT, AlState.OP): (0x11, 0x0011),
    (AlState.PREOP, AlState.INIT): (0x01, 0),
    (AlState.PREOP, AlState.PREOP): (0x02, 0),
    (AlState.PREOP, AlState.BOOT): (0x12, 0x0011),
    (AlState.PREOP, AlState.SAFEOP): (0x04, 0),
    (AlState.PREOP, AlState.OP): (0x12, 0x0011),
    (AlState.SAFEOP, AlState.INIT): (0x01, 0),
    (AlState.SAFEOP, AlState.PREOP): (0x02, 0),
    (AlState.SAFEOP, AlState.BOOT): (0x14, 0x0011),
    (AlState.SAFEOP, AlState.SAFEOP): (0x04, 0),
    (AlState.SAFEOP, AlState.OP): (0x04, 0),  # until the first outputs (decision F5)
    (AlState.OP, AlState.INIT): (0x01, 0),
    (AlState.OP, AlState.PREOP): (0x02, 0),
    (AlState.OP, AlState.BOOT): (0x18, 0x0011),
    (AlState.OP, AlState.SAFEOP): (0x04, 0),
    (AlState.OP, AlState.OP): (0x08, 0),
}


def _al(m: TinyMaster) -> tuple[int, int]:
    st = struct.unpack("<H", m.aprd(0, 0x0130, 2).data)[0]
    code = struct.unpack("<H", m.aprd(0, 0x0134, 2).data)[0]
    return st, code


def _goto(m: TinyMaster, state: AlState) -> None:
    m.apwr(0, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(0, 0x0808, struct.pack("<HHBBBB", 0x1080, 128, 0x22, 0, 1, 0))
    m.apwr(0, 0x0810, struct.pack("<HHBBBB", 0x1100, 12, 0x64, 0, 1, 0))
    m.apwr(0, 0x0818, struct.pack("<HHBBBB", 0x1200, 17, 0x20, 0, 1, 0))
    path = {
        AlState.INIT: [],
        AlState.PREOP: [2],
        AlState.SAFEOP: [2, 4],
        AlState.OP: [2, 4, 8],
    }[state]
    for s in path:
        if s == 8:
            m.apwr(0, 0x1100, bytes(12))  # outputs: SAFEOP -> OP needs them (decision F5)
        m.apwr(0, 0x0120, struct.pack("<H", s))
    assert _al(m) == (int(state), 0)


@pytest.mark.parametrize(("start", "req"), sorted(EXPECTED))
def test_transition(start: AlState, req: AlState) -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    _goto(m, start)
    m.apwr(0, 0x0120, struct.pack("<H", int(req)))
    assert _al(m) == EXPECTED[(start, req)]


@pytest.mark.parametrize("code", [0, 5, 6, 7, 9, 15])
def test_unknown_state_codes(code: int) -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    _goto(m, AlState.PREOP)
    m.apwr(0, 0x0120, struct.pack("<H", code))
    assert _al(m) == (0x12, 0x0012)


def test_every_pair_is_covered() -> None:
    assert {(a, b) for a in STATES if a != AlState.BOOT for b in STATES} == set(EXPECTED)
