"""The ramp generator and the motor model (TMC211 §5.1.2-5.1.7, §7.3, §7.4)."""

from __future__ import annotations

import itertools

from ecatsim.lin.motion import TICK_S, Motor, Profile, Ramp, wrap

P = Profile(vmax=3647.0, vmin=112.0, acc=3609.0 * 16)


def run(r: Ramp, target: int, p: Profile, limit: int = 100_000) -> int:
    for n in range(limit):
        r.step(target, p)
        if r.v == 0.0 and r.x == target:
            return n + 1
    raise AssertionError("never arrived")


def test_arrives_exactly_with_the_analytic_duration() -> None:
    r = Ramp()
    ticks = run(r, 16000, P)
    assert r.x == 16000.0
    vmax, vmin, acc = P.vmax, P.vmin, P.acc
    ramp = (vmax**2 - vmin**2) / (2 * acc)
    expect = 2 * (vmax - vmin) / acc + (16000 - 2 * ramp) / vmax
    assert abs(ticks * TICK_S - expect) < 0.01


def test_rectangular_profile_runs_at_vmin() -> None:
    r = Ramp()
    ticks = run(r, 1120, Profile(3647.0, 112.0, 1.0, rectangular=True))
    assert abs(ticks * TICK_S - 10.0) < 2 * TICK_S


def test_shortest_way_on_the_16_bit_circle() -> None:
    r = Ramp()
    r.x = 32760.0
    run(r, -32760, P)
    assert r.x == -32760.0
    assert wrap(32768.0) == -32768.0


def test_reversal_is_a_linear_zero_crossing() -> None:
    r = Ramp()
    for _ in range(200):
        r.step(20000, P)
    assert r.v == P.vmax
    speeds = []
    while r.v > 0:
        r.step(0, P)
        speeds.append(r.v)
    assert all(a - b > P.acc * TICK_S * 0.99 for a, b in itertools.pairwise(speeds))
    assert r.motion_status(False) in (0b101, 0b000, 0b100)
    run(r, 0, P)
    assert r.x == 0.0


def test_motion_status_codes() -> None:
    r = Ramp()
    r.step(10000, P)
    assert r.motion_status(False) == 0b001  # accelerating, v > 0
    for _ in range(100):
        r.step(10000, P)
    assert r.motion_status(False) == 0b011  # at Vmax
    r.v = -r.v
    assert r.motion_status(False) == 0b111
    r.stop()
    assert r.motion_status(False) == 0b100 and r.motion_status(True) == 0b000


def test_motor_stops_hold_the_rotor_and_count_lost_steps() -> None:
    m = Motor(stops=(-100, 100), switch=(90, 100))
    m.move(150, shaft=0)
    assert m.rotor == 100 and m.lost_steps == 50 and m.switch_closed()
    m.move(50, shaft=1)  # Shaft turns the other way
    assert m.rotor == 50 and not m.switch_closed()
