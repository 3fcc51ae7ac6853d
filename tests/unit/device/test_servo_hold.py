"""``Servo._run`` ends at a fixed point exactly as the full loop would (decision P81).

A motor holding still (speed 0, currents 0, position error exactly 0, static friction
holding) repeats the very same substep; _run() then ends after the first one. Twin servos,
one with the shortcut off (``fast_hold = False``), run the same random demands (torque,
velocity, position; following windows, the index, trip currents; at rest and moving; tiny
errors that wind the integrators up; the flux axis on and off) and end every run alike,
bit for bit: every field, the substeps done and the reason to stop.

Ref: TMC8670 §5.1.7-5.1.10 (current, velocity and position loops).
"""

from __future__ import annotations

import math
import random
import struct

import pytest

from ecatsim.device.servo import POSITION, TORQUE, VELOCITY, MotorParams, Servo

#: every field a run reads or writes
STATE = (
    "angle",
    "omega",
    "iq_ma",
    "iq_ref_ma",
    "id_ma",
    "id_ref_ma",
    "iq_integ",
    "id_integ",
    "integ",
    "i_limit_ma",
    "vel_limit_rpm",
)


#: the fields one substep hands the next (iq_ref, emf, ... are set anew before being read)
CARRIED = ("angle", "omega", "iq_ma", "iq_integ", "integ", "id_ma", "id_integ")


def carried(s: Servo) -> tuple[bytes, ...]:
    return tuple(struct.pack("<d", float(getattr(s, k))) for k in CARRIED)


def bits(s: Servo) -> tuple[bytes, ...]:
    """The state's doubles as bytes: -0.0 is not 0.0, nan is itself."""
    doubles = [struct.pack("<d", float(getattr(s, k))) for k in STATE]
    return (*doubles, struct.pack("<i", s.stopped))


def twins(rng: random.Random) -> tuple[Servo, Servo]:
    params = MotorParams(
        ppr=rng.choice([1000, 4096]),
        load=rng.choice([0.0, 0.0, 1.0e-3, 3.0e-3]),
        coulomb=rng.choice([2.0e-3, 2.0e-3, 0.0]),
    )
    fast, full = Servo(params), Servo(params)
    full.fast_hold = False
    return fast, full


def start(rng: random.Random, fast: Servo, full: Servo) -> None:
    """The same start for both: at rest (zeros of either sign), or moving."""
    r = rng.random()
    angle = rng.choice([0.0, -0.0, rng.uniform(-50.0, 50.0), 2 * math.pi * rng.randint(-3, 3)])
    values = {
        "angle": angle,
        "omega": rng.choice([0.0, -0.0, 0.0, rng.uniform(-100.0, 100.0)]) if r < 0.8 else 5.0,
        "iq_ma": rng.choice([0.0, -0.0, 0.0, rng.uniform(-50.0, 50.0)]),
        "iq_integ": rng.choice([0.0, -0.0, 0.0, rng.uniform(-1e-3, 1e-3)]),
        "integ": rng.choice([0.0, -0.0, 0.0, rng.uniform(-200.0, 200.0), 1e-300]),
        "iq_ref_ma": rng.choice([0.0, -0.0, 7.0]),
        "id_ref_ma": rng.choice([0.0] * 6 + [-0.0, 300.0, -150.0]),
        "id_ma": rng.choice([0.0] * 6 + [-0.0, 300.0, 12.5]),
        "id_integ": rng.choice([0.0] * 4 + [-0.0, 1.0]),
        "i_limit_ma": rng.choice([20000.0, 500.0]),
        "vel_limit_rpm": rng.choice([1e9, 300.0]),
    }
    for s in (fast, full):
        for k, v in values.items():
            setattr(s, k, v)


def demand(rng: random.Random, s: Servo) -> tuple[int, float, float, float, float, bool]:
    """A random demand: kind, reference, feed-forward, window, trip current, index."""
    kind = rng.choice([TORQUE, VELOCITY, POSITION, POSITION, POSITION])
    here = s.angle / (2 * math.pi) * s.p.ppr
    if kind == POSITION:
        ref = rng.choice(
            [
                here,  # exactly here: a motor at rest holds still
                float(math.floor(here)),
                here + rng.choice([1e-9, -1e-12, 1e-6]),  # tiny errors: the integrator winds
                here + rng.uniform(-500.0, 500.0),
            ]
        )
    elif kind == VELOCITY:
        ref = rng.choice([0.0, -0.0, 1e-9, rng.uniform(-300.0, 300.0)])
    else:
        ref = rng.choice([0.0, -0.0, 10.0, 20.0, 60.0, rng.uniform(-400.0, 400.0)])
    v_ff = rng.choice([0.0, 0.0, -0.0, rng.uniform(-10.0, 10.0)])
    window = rng.choice([0.0, 0.0, 5.0, 200.0])
    trip = rng.choice([math.inf, math.inf, 15000.0, 30.0, 0.0])
    return kind, ref, v_ff, window, trip, rng.random() < 0.4


@pytest.mark.parametrize("seed", range(24))
def test_the_fixed_point_shortcut_is_the_full_loop(seed: int) -> None:
    rng = random.Random(seed)
    shortcuts = 0
    for _ in range(30):
        fast, full = twins(rng)
        start(rng, fast, full)
        for _ in range(40):
            kind, ref, v_ff, window, trip, index = demand(rng, fast)
            n = rng.choice([1, 2, 3, 10, 10, 10, 57])
            before = carried(fast)
            got = fast._run(n, kind, ref, v_ff, window, trip, index)
            want = full._run(n, kind, ref, v_ff, window, trip, index)
            assert (got, fast.stopped) == (want, full.stopped)
            assert bits(fast) == bits(full)
            if n > 1 and got == n and carried(fast) == before:
                shortcuts += 1  # a fixed point: the shortcut ended the fast twin's run
            if rng.random() < 0.1:
                start(rng, fast, full)
            elif rng.random() < 0.2:
                for s in (fast, full):  # to rest, for the holds to come
                    s.omega = s.iq_ma = s.iq_integ = s.integ = 0.0
    assert shortcuts > 10, shortcuts  # the shortcut ran


def test_a_motor_holding_still_is_a_fixed_point() -> None:
    """Enabled at rest on its own position: every run of 10 substeps leaves the state as
    it was, and so takes one substep's work (decision P81)."""
    s = Servo(MotorParams())
    s.angle = 1.5
    here = s.angle / (2 * math.pi) * s.p.ppr
    before = bits(s)
    for _ in range(5):
        assert s._run(10, POSITION, here, 0.0, 50.0, 15000.0, True) == 10
    assert bits(s) == before


def test_a_signed_zero_is_not_the_same_state() -> None:
    """-0.0 == 0.0, but a substep may treat them apart: no shortcut across a sign change."""
    from ecatsim.device import servo as servo_module

    same = servo_module._same
    assert same(0.0, 0.0) and same(-0.0, -0.0) and same(1.5, 1.5)
    assert not same(0.0, -0.0) and not same(-0.0, 0.0)
    assert not same(math.nan, math.nan) and not same(1.0, 2.0)


@pytest.mark.parametrize(
    ("kind", "ref", "field", "value"),
    [
        # velocity PI: out = 12.5 * 1.0 - 12.5 = 0 holds the current at 0, the integrator
        # moves by 960 * 1.0 * 100 us: the second substep drives current
        (VELOCITY, 1.0, "integ", -12.5),
        # current PI: v = 4 * 0.25 - 1.0 = 0 keeps iq at 0, its integrator moves by
        # 4000 * 0.25 * 100 us: the second substep's voltage differs
        (TORQUE, 250.0, "iq_integ", -1.0),
    ],
)
def test_an_integrator_alone_moving_is_no_fixed_point(
    kind: int, ref: float, field: str, value: float
) -> None:
    """The first substep leaves everything but one integrator as it was: the run goes on
    (every carried value is compared, not only the motion)."""
    fast, full = Servo(MotorParams()), Servo(MotorParams())
    full.fast_hold = False
    for s in (fast, full):
        setattr(s, field, value)
    one = Servo(MotorParams())
    setattr(one, field, value)
    one._run(1, kind, ref, 0.0, 0.0, math.inf, False)
    assert (one.angle, one.omega, one.iq_ma) == (0.0, 0.0, 0.0)  # the case it is meant as
    assert getattr(one, field) != value
    assert fast._run(10, kind, ref, 0.0, 0.0, math.inf, False) == 10
    full._run(10, kind, ref, 0.0, 0.0, math.inf, False)
    assert bits(fast) == bits(full)
    assert fast.iq_ma != 0.0  # the later substeps ran
