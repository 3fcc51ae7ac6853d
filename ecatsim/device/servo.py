"""Simulated servo: motor and load, cascaded loops, encoder; integrated on fixed substeps.

Mechanics: J dw/dt = Kt*iq - B*w - Tc*sign(w) - T_load. The FOC current loops (torque iq
and flux id, 2041h) are digital PIs at the substep rate driving the winding, an R-L circuit
with back EMF Ke*w (Ke = Kt) integrated exactly over each substep (zero-order hold), the
voltage limited by the supply; the velocity loop is a PI (2042h), the position loop a P
(2043h) with velocity feed-forward. Limits: 2050h, 6072h, 607Fh. Every substep has the
same length, so the trajectory does not depend on how often the master sends frames.
Ref: TMC8670 §5.1.7-5.1.10, §5.1.14; CiA 402-2 §10-§12.
"""

from __future__ import annotations

import math

# the same module under a second name: the compiled core takes this one from C's libm
# (servo.pxd cimports libc.math as _libm), so _libm.copysign is a C call there
import math as _libm
from dataclasses import dataclass

TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0  # rad/s per rpm
#: the two as C doubles in the compiled core (the public names stay Python floats)
_TWO_PI = TWO_PI
_RPM = RPM

# What Servo.run's reference is, and why it stopped early.
TORQUE, VELOCITY, POSITION = 0, 1, 2
STOP_NONE, STOP_FOLLOWING, STOP_OVERCURRENT, STOP_INDEX = 0, 1, 2, 3
#: the same as C integers in the compiled core (a module global is a dict lookup there)
_TORQUE, _POSITION = TORQUE, POSITION
_STOP_NONE, _STOP_FOLLOWING, _STOP_OVERCURRENT, _STOP_INDEX = (
    STOP_NONE,
    STOP_FOLLOWING,
    STOP_OVERCURRENT,
    STOP_INDEX,
)


@dataclass(frozen=True, slots=True)
class MotorParams:
    """Motor, load and encoder. Units SI unless named."""

    motor_type: str = "pmsm"  # pmsm or stepper (2020h:01 0 = PMSM, 1 = 2-phase stepper)
    pole_pairs: int = 4
    kt: float = 0.05  # Nm/A
    inertia: float = 2.0e-5  # kg m^2 (rotor + load)
    viscous: float = 1.0e-5  # Nm/(rad/s)
    coulomb: float = 2.0e-3  # Nm
    load: float = 0.0  # Nm, external, opposing positive rotation
    ppr: int = 4096  # encoder counts per revolution (2081h:02)
    resistance: float = 1.0  # ohm, winding (phase)
    inductance: float = 1.0e-3  # H, winding (d and q alike)
    supply_voltage: float = 48.0  # V, the most the current loop can apply
    max_current_ma: int = 20000
    substep: float = 1.0e-4  # s


class Gains:
    """Loop gains in engineering units (mapped from 2041h-2043h by the drive).

    A plain class with the constructor, ``repr`` and equality of a slots dataclass:
    compiled, an extension type with C doubles, which the substep loop reads as fields
    (servo.pxd, decision P15)."""

    __slots__ = FIELDS = ("cur_kp", "cur_ki", "flux_kp", "flux_ki", "vel_kp", "vel_ki", "pos_kp")

    cur_kp: float  # V per A (2041h:05 / 256; L / 250 us)
    cur_ki: float  # V per A*s (2041h:06; R / 250 us)
    flux_kp: float  # V per A (2041h:07 / 256)
    flux_ki: float  # V per A*s (2041h:08)
    vel_kp: float  # mA per rpm
    vel_ki: float  # mA per rpm*s
    pos_kp: float  # rpm per count

    def __init__(
        self,
        cur_kp: float = 4.0,
        cur_ki: float = 4000.0,
        flux_kp: float = 4.0,
        flux_ki: float = 4000.0,
        vel_kp: float = 12.5,
        vel_ki: float = 960.0,
        pos_kp: float = 0.7,
    ) -> None:
        self.cur_kp = cur_kp
        self.cur_ki = cur_ki
        self.flux_kp = flux_kp
        self.flux_ki = flux_ki
        self.vel_kp = vel_kp
        self.vel_ki = vel_ki
        self.pos_kp = pos_kp

    def __repr__(self) -> str:
        return "Gains(" + ", ".join(f"{f}={getattr(self, f)!r}" for f in Gains.FIELDS) + ")"

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        fields = Gains.FIELDS  # compared as field tuples, as a dataclass does
        return tuple(getattr(self, f) for f in fields) == tuple(getattr(other, f) for f in fields)

    __hash__ = None  # type: ignore[assignment]  # mutable, compared by value


class Servo:
    """State and one substep of the motor and its loops."""

    __slots__ = (
        "_coulomb",
        "_dt",
        "_inertia",
        "_kt",
        "_load",
        "_ppr",
        "_resistance",
        "_viscous",
        "_vmax_v",
        "angle",
        "decay",
        "fast_hold",
        "gains",
        "i_limit_ma",
        "id_integ",
        "id_ma",
        "id_ref_ma",
        "integ",
        "iq_integ",
        "iq_ma",
        "iq_ref_ma",
        "omega",
        "p",
        "stopped",
        "vel_limit_rpm",
    )

    def __init__(self, params: MotorParams) -> None:
        self.p = params
        self.gains = Gains()
        self.angle = 0.0  # rad, mechanical
        self.omega = 0.0  # rad/s
        self.iq_ma = 0.0
        self.iq_ref_ma = 0.0
        self.id_ma = 0.0
        self.id_ref_ma = 0.0  # flux target (2041h:03)
        self.iq_integ = 0.0  # V, current PI integrators
        self.id_integ = 0.0
        self.integ = 0.0
        # R-L winding over one substep: i' = i*decay + (1 - decay) * v / R
        self.decay = math.exp(-params.resistance * params.substep / params.inductance)
        # the constants of run()'s loop, from the (frozen) motor parameters: C doubles in
        # the compiled core, read as fields (no tuple unpacked per call; decision P51)
        self._dt = float(params.substep)
        self._ppr = float(params.ppr)
        self._kt = float(params.kt)
        self._load = float(params.load)
        self._viscous = float(params.viscous)
        self._coulomb = float(params.coulomb)
        self._inertia = float(params.inertia)
        self._vmax_v = float(params.supply_voltage)
        self._resistance = float(params.resistance)
        self.i_limit_ma = float(params.max_current_ma)
        self.vel_limit_rpm = 1e9
        #: why the last _run() stopped early (STOP_NONE: it did every substep)
        self.stopped = STOP_NONE
        #: _run() ends at the first substep that leaves the state as it found it, bit for
        #: bit (a motor holding still): the substeps after it would repeat it (decision P81)
        self.fast_hold = True

    @property
    def motor(self) -> tuple[float, ...]:
        """The constants of run()'s loop: substep, ppr, kt, load, viscous, coulomb,
        inertia, supply voltage, resistance."""
        return (
            self._dt,
            self._ppr,
            self._kt,
            self._load,
            self._viscous,
            self._coulomb,
            self._inertia,
            self._vmax_v,
            self._resistance,
        )

    # ----------------------------------------------------------------- feedback
    @property
    def counts(self) -> int:
        """Encoder position (quantised). Ref: TMC8670 §5.1.14 (2081h)."""
        return self.read_counts()

    @property
    def rpm(self) -> float:
        return self.read_rpm()

    def read_counts(self) -> int:
        """``counts`` as a method: the compiled drive calls it in C (a property of another
        module's class is a Python attribute lookup there)."""
        return int(self.floor_counts())

    def floor_counts(self) -> float:
        """``counts`` as a whole float (a C double to the compiled drive, no int object)."""
        return _floor(self.angle / _TWO_PI * self._ppr)

    def read_rpm(self) -> float:
        """``rpm`` as a method (see read_counts)."""
        return self.omega / _RPM

    def counts_per_s(self, rpm: float) -> float:
        return rpm * self.p.ppr / 60.0

    def torque(self) -> float:
        return self.p.kt * self.iq_ma / 1000.0

    # ----------------------------------------------------------------- control
    def reset_integrators(self) -> None:
        self.integ = 0.0
        self.iq_integ = self.id_integ = 0.0

    def _current_loop(
        self, ref_ma: float, i_ma: float, integ: float, kp: float, ki: float, emf: float
    ) -> tuple[float, float]:
        """One substep of a current PI (anti-windup by clamping at the supply voltage) on
        the R-L winding with back EMF ``emf``: (new current mA, new integrator V). The
        torque axis runs the same arithmetic inlined in run().
        Ref: TMC8670 §5.1.7 (2041h); decision D15."""
        p = self.p
        err = (ref_ma - i_ma) / 1000.0  # A
        v = kp * err + integ + emf  # the back EMF is fed forward (decoupled)
        vmax = p.supply_voltage
        if -vmax < v < vmax:
            integ += ki * err * p.substep  # anti-windup: hold while saturated
        v = max(-vmax, min(vmax, v))
        i = i_ma / 1000.0
        i = i * self.decay + (1.0 - self.decay) * (v - emf) / p.resistance
        return i * 1000.0, integ

    def step(self, iq_ref_ma: float) -> None:
        """One substep with a torque current reference."""
        self.run(1, TORQUE, iq_ref_ma)

    def run(
        self,
        n: int,
        kind: int,
        ref: float,
        v_ff_rpm: float = 0.0,
        window: float = 0.0,
        i_trip_ma: float = math.inf,
        index: bool = False,
    ) -> tuple[int, int]:
        """Up to ``n`` substeps with a constant demand; returns (substeps done, why it
        stopped early or STOP_NONE): ``_run`` with its reason as a tuple.

        ``kind`` says what ``ref`` is: TORQUE (current mA), VELOCITY (rpm, through the
        velocity PI) or POSITION (counts, through the position P with velocity feed-forward
        ``v_ff_rpm``, then the velocity PI). Each substep: the demand's loops, the torque
        current PI on the winding (and the flux PI if it carries current), then mechanics
        (semi-implicit Euler) with viscous and Coulomb friction. It stops early, with the
        substep count so far, before a substep where the position error exceeds ``window``
        (POSITION, window > 0: STOP_FOLLOWING), after one where |iq| exceeds ``i_trip_ma``
        (STOP_OVERCURRENT) and, with ``index``, after one that crossed angle 0 mod 2 pi
        (STOP_INDEX): the caller acts, then continues.
        One loop, all state in locals (typed doubles in the compiled core, servo.pxd):
        this is the frame path's largest cost per drive.
        Ref: TMC8670 §5.1.7-5.1.10; decisions D15, P2.
        """
        done = self._run(n, kind, ref, v_ff_rpm, window, i_trip_ma, index)
        return done, self.stopped

    def _run(
        self,
        n: int,
        kind: int,
        ref: float,
        v_ff_rpm: float,
        window: float,
        i_trip_ma: float,
        index: bool,
    ) -> int:
        """run() returning the substeps done, its reason to stop in ``stopped``: a C call
        with C results in the compiled core, no tuple per call (decision P51).
        Ref: TMC8670 §5.1.7-5.1.10."""
        dt = self._dt
        ppr = self._ppr
        kt = self._kt
        load = self._load
        viscous = self._viscous
        coulomb = self._coulomb
        inertia = self._inertia
        vmax_v = self._vmax_v
        resistance = self._resistance
        g = self.gains
        decay = self.decay
        lim = self.i_limit_ma
        vlim = self.vel_limit_rpm
        vel_kp = g.vel_kp
        vel_ki = g.vel_ki
        pos_kp = g.pos_kp
        cur_kp = g.cur_kp
        cur_ki = g.cur_ki
        angle = self.angle
        omega = self.omega
        iq = self.iq_ma
        iq_integ = self.iq_integ
        integ = self.integ
        iq_ref = self.iq_ref_ma
        flux = bool(self.id_ref_ma or self.id_ma)
        # the flux axis's state before the first substep (the loop updates it in self)
        id_ma = self.id_ma
        id_integ = self.id_integ
        # whether to look for the fixed point after the first substep (decision P81)
        hold = self.fast_hold and n > 1
        # the module's constants as locals (C constants in the compiled core)
        torque_kind = _TORQUE
        position_kind = _POSITION
        done = 0
        why = _STOP_NONE
        # the revolution at the substep's start: the one the last substep ended in (the
        # angle does not change in between), found at the first substep (decision P60)
        rev = 0.0
        rev_known = False
        # floor(q) == rev  <=>  rev <= q < rev + 1, rev + 1 exact for |rev| < 2^52: two
        # comparisons instead of a floor per substep (decision P77)
        rev_hi = 0.0
        rev_cmp = False
        while done < n:
            if kind == torque_kind:
                out = ref
            else:
                if kind == position_kind:
                    # 2 pi and RPM as literals (the same doubles as TWO_PI, RPM: a test
                    # says so): compiled, no test for a zero divisor per substep (P51)
                    err_p = ref - angle / 6.283185307179586 * ppr
                    if window and abs(err_p) > window:
                        why = _STOP_FOLLOWING
                        break
                    v_ref = pos_kp * err_p + v_ff_rpm
                else:
                    v_ref = ref
                # velocity PI, anti-windup by clamping
                v_ref = -vlim if v_ref < -vlim else vlim if v_ref > vlim else v_ref
                err = v_ref - omega / 0.10471975511965977
                out = vel_kp * err + integ
                if -lim < out < lim:
                    integ += vel_ki * err * dt
            # torque current PI on the winding (see _current_loop)
            iq_ref = -lim if out < -lim else lim if out > lim else out
            emf = kt * omega
            err_a = (iq_ref - iq) / 1000.0
            v = cur_kp * err_a + iq_integ + emf
            if -vmax_v < v < vmax_v:
                iq_integ += cur_ki * err_a * dt
            v = -vmax_v if v < -vmax_v else vmax_v if v > vmax_v else v
            iq = (iq / 1000.0 * decay + (1.0 - decay) * (v - emf) / resistance) * 1000.0
            if flux:
                self.id_ma, self.id_integ = self._current_loop(
                    self.id_ref_ma, self.id_ma, self.id_integ, g.flux_kp, g.flux_ki, 0.0
                )
            if iq_ref == 0.0 and omega == 0.0 and abs(iq) < 1e-3:
                iq = iq_integ = 0.0
            # mechanics
            torque = kt * iq / 1000.0
            drive = torque - load - viscous * omega
            if omega > 1e-9:
                drive -= coulomb
            elif omega < -1e-9:
                drive += coulomb
            elif abs(drive) <= coulomb:
                drive = 0.0  # static friction holds
            else:
                drive -= coulomb if drive > 0.0 else -coulomb  # |drive| > coulomb >= 0
            new = omega + drive / inertia * dt
            if omega != 0.0 and (new > 0) != (omega > 0) and abs(torque - load) <= coulomb:
                new = 0.0  # friction stops the motor, it does not reverse it
            if index and not rev_known:
                rev = _floor(angle / 6.283185307179586)
                rev_known = True
                rev_cmp = -4.0e15 < rev < 4.0e15
                rev_hi = rev + 1.0
            omega = new
            angle += omega * dt
            done += 1
            if abs(iq) > i_trip_ma:
                why = _STOP_OVERCURRENT
                break
            if index:
                q = angle / 6.283185307179586
                if not (rev_cmp and rev <= q < rev_hi):  # else floor(q) is rev
                    now = _floor(q)  # nan and infinities raise here as before
                    if now != rev:
                        why = _STOP_INDEX
                        break
            # the first substep did not stop and left every value the next one reads as
            # it was, bit for bit (iq_ref, emf, ... are set anew before being read; nan is
            # never the same): the others, with the same demand, would repeat it exactly,
            # stops included (decision P81)
            if (
                done == 1
                and hold
                and _same(angle, self.angle)
                and _same(omega, self.omega)
                and _same(iq, self.iq_ma)
                and _same(iq_integ, self.iq_integ)
                and _same(integ, self.integ)
                and (not flux or (_same(self.id_ma, id_ma) and _same(self.id_integ, id_integ)))
            ):
                done = n
        self.angle = angle
        self.omega = omega
        self.iq_ma = iq
        self.iq_integ = iq_integ
        self.integ = integ
        self.iq_ref_ma = iq_ref
        self.stopped = why
        return done


def _same(a: float, b: float) -> bool:
    """Whether ``a`` and ``b`` are the same double, bit for bit for the values arithmetic
    makes: equal and of the same sign where zero (0.0 and -0.0 differ, nan is never the
    same). IEEE 754 §5.5.1 (copySign), §5.11 (comparisons)."""
    return a == b and (a != 0.0 or _libm.copysign(1.0, a) == _libm.copysign(1.0, b))


def _floor(x: float) -> float:
    """``math.floor(x)`` as a float: only compared with another floor, so the result is the
    same; C arithmetic in the compiled core, where ``math.floor`` is a Python call (nan
    and infinities still raise as math.floor does; from 2**52 on every float is whole)."""
    if not -4.0e18 < x < 4.0e18:
        return float(math.floor(x))
    k = int(x)
    if x < k:
        k -= 1
    return float(k)


class Profile:
    """Trapezoidal point-to-point generator in counts (pp). Ref: CiA 402-2 §12.3."""

    __slots__ = ("acc", "dec", "pos", "target", "vel", "vmax")

    def __init__(self) -> None:
        self.pos = 0.0  # counts
        self.vel = 0.0  # counts/s
        self.target = 0.0
        self.vmax = 0.0
        self.acc = 1.0
        self.dec = 1.0

    def step(self, dt: float) -> None:
        """Advance the demand by dt: accelerate, cruise, and brake so as to stop exactly
        at the target (the braking rate is v^2 / 2d, which is the profile deceleration
        within one substep)."""
        rem = self.target - self.pos
        if rem == 0.0 and self.vel == 0.0:
            return
        direction = 1.0 if rem > 0 or (rem == 0 and self.vel < 0) else -1.0
        v = self.vel * direction  # speed towards the target
        dist = abs(rem)
        if v < 0:  # moving away from the target: brake first
            v_new = min(0.0, v + self.dec * dt)
            self.pos += direction * (v + v_new) / 2 * dt
            self.vel = direction * v_new
            return
        v_try = (
            min(self.vmax, v + self.acc * dt)
            if v < self.vmax
            else max(self.vmax, v - self.dec * dt)
        )
        if v_try * v_try / (2.0 * self.dec) <= dist - (v + v_try) / 2 * dt:
            v_new = v_try
        else:
            d_req = v * v / (2.0 * dist) if dist > 0 else self.dec
            v_new = max(0.0, v - max(d_req, 1e-12) * dt)
            if v == 0.0:
                v_new = min(self.acc * dt, self.vmax)  # start of a very short move
        travel = (v + v_new) / 2 * dt
        if travel >= dist or (v_new == 0.0 and v > 0.0):
            self.pos = self.target
            self.vel = 0.0
            return
        self.pos += direction * travel
        self.vel = direction * v_new


def ramp(value: float, target: float, up: float, down: float, dt: float) -> float:
    """Velocity ramp towards ``target`` with acceleration ``up``/deceleration ``down``."""
    if value == target:
        return value
    speeding_up = abs(target) > abs(value) and (target >= 0) == (value >= 0)
    rate = (up if speeding_up else down) * dt
    if value < target:
        return min(target, value + rate)
    return max(target, value - rate)
