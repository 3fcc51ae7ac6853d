"""The compiled core's servo loop against the same source run as Python (servo.py): the
same state, bit for bit, and the same early stops, over random motors, gains and demands.
Ref: ecatsim/device/servo.py Servo.run; decision P2."""

from __future__ import annotations

import math
import random
from typing import Any

import pytest

from ecatsim.device import servo
from ecatsim.device.servo import (
    POSITION,
    STOP_FOLLOWING,
    STOP_INDEX,
    STOP_NONE,
    STOP_OVERCURRENT,
    TORQUE,
    VELOCITY,
    MotorParams,
    Servo,
)
from tests.support.core import require_compiled, source_twin

STATE = ("angle", "omega", "iq_ma", "iq_integ", "integ", "iq_ref_ma")


@pytest.fixture(autouse=True)
def _require_compiled() -> None:
    require_compiled(servo)


def pair(rng: random.Random) -> tuple[Servo, Servo]:
    """A servo of the compiled core and one of the same source run as Python."""
    pure = source_twin(servo)
    motor: dict[str, Any] = dict(
        kt=rng.uniform(0.01, 0.2),
        inertia=rng.uniform(5e-6, 1e-4),
        viscous=rng.uniform(0.0, 5e-5),
        coulomb=rng.choice([0.0, rng.uniform(0.0, 1e-2)]),
        load=rng.choice([0.0, rng.uniform(-5e-3, 5e-3)]),
        ppr=rng.choice([1000, 4096, 10000]),
        resistance=rng.uniform(0.3, 5.0),
        inductance=rng.uniform(2e-4, 5e-3),
        supply_voltage=rng.choice([12.0, 24.0, 48.0]),
    )
    a, b = Servo(MotorParams(**motor)), pure.Servo(pure.MotorParams(**motor))
    assert type(a) is not type(b)
    gains = {
        "vel_kp": rng.uniform(1.0, 30.0),
        "vel_ki": rng.uniform(0.0, 3000.0),
        "pos_kp": rng.uniform(0.1, 2.0),
        "cur_kp": rng.uniform(0.5, 8.0),
        "cur_ki": rng.uniform(100.0, 8000.0),
    }
    i_limit = rng.uniform(500.0, 20000.0)
    vel_limit = rng.choice([1e9, rng.uniform(100.0, 3000.0)])
    for s in (a, b):
        for k, v in gains.items():
            setattr(s.gains, k, v)
        s.i_limit_ma = i_limit
        s.vel_limit_rpm = vel_limit
    return a, b


def state(s: Servo) -> tuple[float, ...]:
    return tuple(getattr(s, k) for k in STATE)


@pytest.mark.parametrize("seed", range(60))
def test_compiled_loop_matches_its_source_bit_for_bit(seed: int) -> None:
    rng = random.Random(seed)
    a, b = pair(rng)
    for _ in range(40):
        kind = rng.choice([TORQUE, VELOCITY, POSITION])
        ref = {
            TORQUE: rng.uniform(-25000.0, 25000.0),
            VELOCITY: rng.uniform(-4000.0, 4000.0),
            POSITION: a.angle / (2 * math.pi) * a.p.ppr + rng.uniform(-5000.0, 5000.0),
        }[kind]
        args = (
            rng.randint(1, 30),
            kind,
            ref,
            rng.uniform(-500.0, 500.0),
            rng.choice([0.0, rng.uniform(10.0, 3000.0)]),
            rng.choice([math.inf, rng.uniform(1000.0, 20000.0)]),
            rng.random() < 0.5,
        )
        ra, rb = a.run(*args), b.run(*args)
        assert ra == rb
        assert state(a) == state(b)


def test_every_early_stop_is_reached() -> None:
    """Demands like those above reach each reason for stopping (so the comparison covers
    every exit of the loop)."""
    seen = set()
    for seed in range(60):
        rng = random.Random(seed)
        a, _ = pair(rng)
        for _ in range(40):
            kind = rng.choice([TORQUE, VELOCITY, POSITION])
            ref = rng.uniform(-25000.0, 25000.0)
            _, why = a.run(30, kind, ref, 0.0, rng.choice([0.0, 50.0]), 3000.0, True)
            seen.add(why)
    assert seen == {STOP_NONE, STOP_FOLLOWING, STOP_OVERCURRENT, STOP_INDEX}
