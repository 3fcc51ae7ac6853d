"""Simulated servo: motor and load, cascaded loops, encoder; integrated on fixed substeps.

Mechanics: J dw/dt = Kt*iq - B*w - Tc*sign(w) - T_load. The FOC current loops (torque iq
and flux id, 2041h) are digital PIs at the substep rate driving the winding, an R-L circuit
with back EMF Ke*w (Ke = Kt) integrated exactly over each substep (zero-order hold), the
voltage limited by the supply; the velocity loop is a PI (2042h), the position loop a P
(2043h) with velocity feed-forward. Limits: 2050h, 6072h, 607Fh. Every substep has the
same length, so the trajectory does not depend on how often the master sends frames.
Ref: seed 004 §5.1.7-5.1.10, §5.1.14; CiA 402-2 §10-§12.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

TWO_PI = 2.0 * math.pi
RPM = TWO_PI / 60.0  # rad/s per rpm


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


@dataclass(slots=True)
class Gains:
    """Loop gains in engineering units (mapped from 2041h-2043h by the drive)."""

    cur_kp: float = 4.0  # V per A (2041h:05 / 256; L / 250 us)
    cur_ki: float = 4000.0  # V per A*s (2041h:06; R / 250 us)
    flux_kp: float = 4.0  # V per A (2041h:07 / 256)
    flux_ki: float = 4000.0  # V per A*s (2041h:08)
    vel_kp: float = 12.5  # mA per rpm
    vel_ki: float = 960.0  # mA per rpm*s
    pos_kp: float = 0.7  # rpm per count


class Servo:
    """State and one substep of the motor and its loops."""

    __slots__ = (
        "angle",
        "decay",
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
        self.i_limit_ma = float(params.max_current_ma)
        self.vel_limit_rpm = 1e9

    # ----------------------------------------------------------------- feedback
    @property
    def counts(self) -> int:
        """Encoder position (quantised). Ref: seed 004 §5.1.14 (2081h)."""
        return math.floor(self.angle / TWO_PI * self.p.ppr)

    @property
    def rpm(self) -> float:
        return self.omega / RPM

    def counts_per_s(self, rpm: float) -> float:
        return rpm * self.p.ppr / 60.0

    def torque(self) -> float:
        return self.p.kt * self.iq_ma / 1000.0

    # ----------------------------------------------------------------- control
    def reset_integrators(self) -> None:
        self.integ = 0.0
        self.iq_integ = self.id_integ = 0.0

    def current_from_velocity(self, v_ref_rpm: float, ff_ma: float = 0.0) -> float:
        """Velocity PI (anti-windup by clamping) -> torque current reference in mA."""
        v_ref = max(-self.vel_limit_rpm, min(self.vel_limit_rpm, v_ref_rpm))
        err = v_ref - self.rpm
        dt = self.p.substep
        g = self.gains
        out = g.vel_kp * err + self.integ + ff_ma
        lim = self.i_limit_ma
        if -lim < out < lim:
            self.integ += g.vel_ki * err * dt
        return max(-lim, min(lim, out))

    def velocity_from_position(self, p_ref: float, v_ff_rpm: float) -> float:
        """Position P with velocity feed-forward -> velocity reference in rpm."""
        return self.gains.pos_kp * (p_ref - self.angle / TWO_PI * self.p.ppr) + v_ff_rpm

    def _current_loop(
        self, ref_ma: float, i_ma: float, integ: float, kp: float, ki: float, emf: float
    ) -> tuple[float, float]:
        """One substep of a current PI (anti-windup by clamping at the supply voltage) on
        the R-L winding with back EMF ``emf``: (new current mA, new integrator V).
        Ref: seed 004 §5.1.7 (2041h); decision D15."""
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
        """One substep: current loop lag, then mechanics (semi-implicit Euler)."""
        p = self.p
        dt = p.substep
        lim = self.i_limit_ma
        self.iq_ref_ma = max(-lim, min(lim, iq_ref_ma))
        g = self.gains
        emf = p.kt * self.omega  # V, Ke = Kt
        self.iq_ma, self.iq_integ = self._current_loop(
            self.iq_ref_ma, self.iq_ma, self.iq_integ, g.cur_kp, g.cur_ki, emf
        )
        if self.id_ref_ma or self.id_ma:
            self.id_ma, self.id_integ = self._current_loop(
                self.id_ref_ma, self.id_ma, self.id_integ, g.flux_kp, g.flux_ki, 0.0
            )
        if self.iq_ref_ma == 0.0 and abs(self.iq_ma) < 1e-3 and self.omega == 0.0:
            self.iq_ma = self.iq_integ = 0.0
        drive = p.kt * self.iq_ma / 1000.0 - p.load - p.viscous * self.omega
        if self.omega > 1e-9:
            drive -= p.coulomb
        elif self.omega < -1e-9:
            drive += p.coulomb
        elif abs(drive) <= p.coulomb:
            drive = 0.0  # static friction holds
        else:
            drive -= math.copysign(p.coulomb, drive)
        new = self.omega + drive / p.inertia * dt
        if (
            self.omega != 0.0
            and (new > 0) != (self.omega > 0)
            and abs(p.kt * self.iq_ma / 1000.0 - p.load) <= p.coulomb
        ):
            new = 0.0  # friction stops the motor, it does not reverse it
        self.omega = new
        self.angle += self.omega * dt


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
