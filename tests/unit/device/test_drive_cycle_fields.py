"""The drive's cycle state held as C fields (decision P51) reads and writes as the Python
values it stands for, in the compiled core and in Python alike: the servo's constants,
``stopped`` beside ``run``'s tuple, the literals of 2 pi and RPM, the drive's times and
last target with None, and the entries the cycle reads bound once.
Ref: ecatsim/device/servo.py, ecatsim/device/drive.py; CiA 402-2 §8."""

from __future__ import annotations

import math

from ecatsim.device import drive, servo
from ecatsim.device.cia402 import PdsState
from ecatsim.device.description import default_description
from ecatsim.device.drive import CSP, Drive
from ecatsim.device.servo import POSITION, STOP_FOLLOWING, STOP_NONE, MotorParams, Servo
from ecatsim.slave.al import AlState
from ecatsim.slave.od_build import build_od

MS = 1_000_000


def test_the_loops_literals_are_two_pi_and_rpm() -> None:
    """Servo._run divides by 6.283185307179586 and 0.10471975511965977 (no test for a
    zero divisor per substep compiled): they are TWO_PI and RPM, bit for bit."""
    assert 6.283185307179586 == servo.TWO_PI == 2.0 * math.pi
    assert 0.10471975511965977 == servo.RPM == 2.0 * math.pi / 60.0


def test_the_motor_constants_are_the_parameters() -> None:
    p = MotorParams(kt=0.07, inertia=3e-5, viscous=2e-5, coulomb=1e-3, load=5e-4, ppr=1000)
    s = Servo(p)
    assert s.motor == (
        p.substep,
        float(p.ppr),
        p.kt,
        p.load,
        p.viscous,
        p.coulomb,
        p.inertia,
        p.supply_voltage,
        p.resistance,
    )
    assert all(type(v) is float for v in s.motor)


def test_run_returns_what_stopped_says() -> None:
    s = Servo(MotorParams())
    assert s.run(10, POSITION, 0.0) == (10, STOP_NONE)
    assert s.stopped == STOP_NONE
    done, why = s.run(10, POSITION, 1e6, 0.0, 5.0)  # far outside a 5-count window
    assert (done, why) == (0, STOP_FOLLOWING)
    assert s.stopped == STOP_FOLLOWING
    assert s.run(3, POSITION, 0.0) == (3, STOP_NONE)
    assert s.stopped == STOP_NONE


def enabled_csp() -> Drive:
    d = Drive(build_od(default_description()))
    d.al_state_changed(AlState.OP, 0)
    d.od.set(0x6060, 0, CSP)
    for k, cw in enumerate((0x06, 0x07, 0x0F)):
        d.od.set(0x6040, 0, cw)
        d.outputs_applied((k + 1) * MS)
    return d


def test_times_and_last_target_read_none_until_set_and_after_reset() -> None:
    d = Drive(build_od(default_description()))
    assert d.t_ns is None and d.last_target is None and d.last_t_ns is None
    d = enabled_csp()
    assert d.state is PdsState.OPERATION_ENABLED
    assert d.t_ns == 3 * MS
    # enabling holds the position: no target from before it (transition 4)
    assert d.last_target is None and d.last_t_ns == 3 * MS
    d.od.set(0x607A, 0, 400)
    d.outputs_applied(4 * MS)
    last: object = getattr(d, "last_target")  # noqa: B009 (mypy narrowed it to None)
    assert last == 400.0 and type(last) is float
    assert d.last_t_ns == 4 * MS
    d.od.set(0x607A, 0, 800)
    d.outputs_applied(5 * MS)
    assert d.v_ff_rpm == (800.0 - 400.0) / 1e-3 * 60.0 / 4096
    for name, value in (("t_ns", 7 * MS), ("last_target", -1.5), ("last_t_ns", 6 * MS)):
        setattr(d, name, value)
        assert getattr(d, name) == value
        setattr(d, name, None)
        assert getattr(d, name) is None
    # no time yet: the next update only takes its time, and then substeps follow from it
    d.update_inputs(9 * MS)
    assert d.t_ns == 9 * MS
    d.update_inputs(10 * MS)
    assert d.t_ns == 10 * MS


def test_the_bound_entries_are_the_ods_own() -> None:
    """The entries bound once are the OD's objects: a write through any path (SDO, PDO,
    od.set) is what the next cycle reads."""
    d = enabled_csp()
    od = d.od
    d.od.entry(0x607A, 0).value = 1234  # as the process image writes it
    d.outputs_applied(4 * MS)
    assert d.q_607a == 1234 and d.last_target == 1234.0
    od.set(0x60B0, 0, 7)  # an SDO download's path
    d.update_inputs(5 * MS)
    assert d.q_60b0 == 7
    assert d.p_demand == 1234 + 7
    od.set(0x6060, 0, drive.CSV)
    d.outputs_applied(6 * MS)
    assert d.mode == drive.CSV
