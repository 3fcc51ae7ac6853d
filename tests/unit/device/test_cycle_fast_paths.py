"""The drive cycle's fast paths do what the full paths do (decisions P75, P77).

- ``Drive._controlword`` skips decode() and step() for a controlword repeated in a state
  where it commanded nothing: twin drives, one with the fast path kept off, go through the
  same random walk of controlwords (held and changed, fault resets, bit 4 in pp), modes
  (valid and not), AL states, quick-stop options and injected faults and end every step
  alike: the object dictionary, the statusword, the state, the logs and the EMCYs.
- ``Servo._run`` tests the index crossing by two comparisons instead of a floor: it stops
  after the very substep a floor per substep finds (single substeps without the index as
  the reference), also at angles where it falls back to the floor.

Ref: CiA 402-2 §8 (FSA), TMC8670 Tables 76, 77; TMC8670 §5.1.14 (encoder index).
"""

from __future__ import annotations

import math
import random

import pytest

from ecatsim.device.description import default_description
from ecatsim.device.drive import CSP, CST, CSV, HM, PP, PV, Drive
from ecatsim.device.servo import POSITION, STOP_INDEX, STOP_NONE, VELOCITY, MotorParams, Servo
from ecatsim.slave.al import AlState
from ecatsim.slave.od_build import build_od
from tests.support.drive_twins import SERVO, Log, drive_state, perturb

MS = 1_000_000


def make() -> tuple[Drive, list[object], list[tuple[object, ...]]]:
    emcys: list[object] = []
    logs: list[tuple[object, ...]] = []
    d = Drive(
        build_od(default_description()),
        None,
        lambda c, r, b: emcys.append((c, r, b)),
        lambda: emcys.append("clear"),
    )
    d.log = Log(logs)
    d.al_state_changed(AlState.OP, 0)
    return d, emcys, logs


def snapshot(d: Drive) -> tuple[object, ...]:
    return drive_state(d)


#: controlwords: the state machine's commands, with and without bit 4 (new set point),
#: bit 6 (relative), bit 7 (fault reset) and bit 8 (halt)
CWS = (0x00, 0x02, 0x06, 0x07, 0x0B, 0x0F, 0x1F, 0x5F, 0x10F, 0x80, 0x86, 0x8F, 0x0E)


@pytest.mark.parametrize("seed", range(16))
def test_the_repeated_controlword_path_is_the_full_path(seed: int) -> None:
    rng = random.Random(seed)
    fast, emcy_a, log_a = make()
    full, emcy_b, log_b = make()
    t = 0
    cw = 0x06
    mode = CSP
    hits = 0
    states: set[object] = set()
    for step in range(600):
        t += rng.choice([MS, MS, MS // 3, 2 * MS])
        sets: dict[int, int] = {0x607A: rng.randint(-3000, 3000) + 20 * step}
        r = rng.random()
        if r < 0.05:
            cw = rng.choice(CWS)  # then held for a while: the repeats take the fast path
        elif r < 0.08:
            cw = (0x06, 0x07, 0x0F)[step % 3]
        elif r < 0.10:
            cw ^= 0x10  # pp's new set point: rising and falling edges
        if r > 0.97:
            mode = rng.choice([PP, PP, PV, HM, CSP, CSV, CST, 7, -1])  # 7, -1: no mode
            sets[0x6060] = mode
        if rng.random() < 0.03:
            sets[0x605A] = rng.choice([0, 2, 5, 6])  # quick stop option
        if rng.random() < 0.03:
            sets[0x6065] = rng.choice([100, 0xFFFFFFFF])
        sets[0x60FF] = rng.randint(-500, 500)
        fault = rng.random()
        al = rng.random()
        sets[0x6040] = cw  # written last
        for d in (fast, full):
            perturb(d, sets, fault, al, t, release=0.02)
        if cw == fast.prev_cw and cw == fast._quiet_cw and fast.state is fast._quiet_state:
            hits += 1
            states.add((fast.state, fast.mode))
        full._quiet_cw = -1  # the full path every time
        for d in (fast, full):
            d.outputs_applied(t)
            d.update_inputs(t)
        assert snapshot(fast) == snapshot(full), f"step {step}"
        assert emcy_a == emcy_b
        assert log_a == log_b
    assert hits > 150, hits  # the fast path ran, in more than one state and mode
    assert len(states) >= 3, states


def test_the_fast_path_still_acts_on_pp_set_points_and_mode_changes() -> None:
    """A controlword held in Operation enabled: bit 4's edge comes from the previous
    cycle, so the held 0x1F starts no second move; a mode change under a held controlword
    still holds the position (CiA 402-2 §12.3; TMC8670 Table 76)."""
    d, _, _ = make()
    d.od.set(0x6060, 0, PP)
    t = 0
    for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F):
        t += MS
        d.od.set(0x6040, 0, cw)
        d.outputs_applied(t)
    assert d.state.name == "OPERATION_ENABLED"
    assert d._quiet_cw == 0x0F
    d.od.set(0x607A, 0, 5000)
    d.od.set(0x6040, 0, 0x1F)
    t += MS
    d.outputs_applied(t)
    assert d.set_point_ack and d.profile.target == 5000.0
    d.od.set(0x607A, 0, 9000)
    for _ in range(3):  # held: no new set point
        t += MS
        d.outputs_applied(t)
    assert d._quiet_cw == 0x1F
    assert d.profile.target == 5000.0
    d.od.set(0x6060, 0, CSP)
    t += MS
    d.outputs_applied(t)
    assert d.mode == CSP
    assert d.profile.target == d.profile.pos  # _hold_here on the mode change


def reference_stop(s: Servo, n: int, kind: int, ref: float) -> tuple[int, int]:
    """The substeps until the angle leaves the revolution it started in, one substep at a
    time without the index test, with math.floor (the loop's check before P77)."""
    rev = math.floor(s.angle / 6.283185307179586)
    for k in range(1, n + 1):
        s.run(1, kind, ref)
        if math.floor(s.angle / 6.283185307179586) != rev:
            return k, STOP_INDEX
    return n, STOP_NONE


@pytest.mark.parametrize("seed", range(8))
def test_the_index_crossing_test_stops_where_a_floor_does(seed: int) -> None:
    rng = random.Random(seed)
    for _ in range(40):
        params = MotorParams(ppr=rng.choice([1000, 4096]))
        a, b = Servo(params), Servo(params)
        start = rng.choice(
            [
                rng.uniform(-20.0, 20.0),
                2 * math.pi * rng.randint(-3, 3) + rng.uniform(-1e-6, 1e-6),
                rng.uniform(-1e17, 1e17),  # beyond 2^52 revolutions' room: the floor
                -0.0,
            ]
        )
        kind = rng.choice([VELOCITY, POSITION])
        ref = rng.uniform(-3000.0, 3000.0)
        if kind == POSITION:
            ref = start / (2 * math.pi) * params.ppr + rng.uniform(-4000.0, 4000.0)
        for s in (a, b):
            s.angle = start
            s.omega = rng.uniform(-300.0, 300.0) if s is a else a.omega
        n = rng.randint(1, 60)
        done, why = a.run(n, kind, ref, index=True)
        assert (done, why) == reference_stop(b, n, kind, ref)
        assert [getattr(a, k) for k in SERVO] == [getattr(b, k) for k in SERVO]


def test_the_index_test_still_raises_on_a_lost_angle() -> None:
    """A nan angle raises in the floor, as before (no index pulse from garbage)."""
    s = Servo(MotorParams())
    s.run(1, VELOCITY, 100.0, index=True)
    s.omega = math.nan
    with pytest.raises(ValueError):
        s.run(3, VELOCITY, 100.0, index=True)
