"""The TMCM-1311's axis on simulated time: ramp generator, two-phase stepper with load,
encoder, closed-loop regulation, stallGuard2/coolStep, I²t supervision, end switches.

Everything advances in fixed steps of :data:`DT_NS` on the clock the module is given, so a
run is a function of the commands and their arrival times only.

Units inside: the rotor angle in motor microsteps (1/256 full step, whatever axis
parameter 140 says), torques in Nm. Positions the host sees are microsteps at the chosen
resolution in open loop and encoder steps in closed loop (§6, §8.4); speeds and
accelerations are pps, microsteps of the chosen resolution per second, in both (§5.7.1,
§6.1, decision T7).

Ref: TMCM-1311 TMCL firmware manual §5.7.1-5.7.4 (motion commands), §6 (axis
parameters), §6.1 (velocity units), §7 (stallGuard2), §8 (closed loop), §9 (switches).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ecatsim.tmcl.protocol import to_signed

#: the physics step
DT_NS = 200_000
DT = DT_NS / 1e9
#: one motor microstep in electrical radians: 4 full steps are one electrical period
ELEC_PER_USTEP = math.pi / 512
#: module current full scale (CS 255, Vsense 0): 3.0 A RMS (§6, axis parameter 6)
I_RMS_MAX_MA = 3000
I_PEAK_MAX_MA = 4200
#: status word bits (axis parameter 18, §6)
SW_TARGET, SW_VELOCITY, SW_CLOSED, SW_POSITION, SW_VELMODE, SW_TORQUE = 1, 2, 4, 8, 16, 32
SW_HOME, SW_LEFT, SW_RIGHT, SW_UNDERV, SW_OVERV, SW_OVERT = 64, 128, 256, 512, 1024, 2048
SW_HOLD, SW_I2T = 4096, 8192
#: driver error flags (axis parameter 208, §6)
DE_STALL, DE_OT, DE_OTPW, DE_S2GA, DE_S2GB, DE_OLA, DE_OLB, DE_STST = 1, 2, 4, 8, 16, 32, 64, 128

POSITION, VELOCITY, TORQUE = 0, 1, 2
#: closed loop: integral gain of the position regulator (1/s, times the gain of 136)
CL_INTEGRAL = 40.0
#: closed loop: advance angle per electrical rad/s of speed difference (s)
CL_DAMPING = 0.0025


@dataclass(slots=True)
class Mechanics:
    """The motor and what it drives (not in the manual: the user's machine, decision T21;
    the electrical data are those of a typical 1.2 Nm NEMA 23 hybrid stepper, T31)."""

    #: torque per RMS ampere of phase current (1.2 Nm holding torque at 3 A)
    torque_per_amp: float = 0.4
    rotor_inertia: float = 3.0e-5
    load_inertia: float = 0.0
    #: Coulomb friction, Nm
    friction: float = 0.01
    #: viscous friction, Nm per rad/s
    viscous: float = 0.002
    #: the machine's load torque, Nm: it resists motion in either direction and holds the
    #: rotor at rest up to its size, like friction; it never turns the rotor (T32)
    load: float = 0.0
    #: phase resistance (ohm) and inductance (H): with the supply they limit the current
    #: the chopper can drive at speed, so the pull-out torque falls with speed (T31)
    resistance: float = 0.75
    inductance: float = 0.0025
    #: the driver's supply voltage, V (axis parameter 153)
    supply_v: float = 24.0


@dataclass(slots=True)
class Switches:
    """Simulated switches at rotor positions in motor microsteps (None: not fitted).

    ``forced`` overrides a switch's raw level (``ecatsim ctl door tmcl switch``)."""

    left: float | None = None
    right: float | None = None
    home: float | None = None
    home_width: float = 2560.0
    forced: dict[str, bool] = field(default_factory=dict)

    def raw(self, name: str, rotor: float) -> bool:
        if name in self.forced:
            return self.forced[name]
        if name == "left":
            return self.left is not None and rotor <= self.left
        if name == "right":
            return self.right is not None and rotor >= self.right
        return self.home is not None and abs(rotor - self.home) <= self.home_width / 2


@dataclass(slots=True)
class Faults:
    """Injected conditions (``ecatsim ctl door tmcl fault``)."""

    overtemperature: bool = False
    encoder_loss: bool = False
    undervoltage: bool = False
    short: bool = False
    #: the rotor is blocked (a mechanical stall)
    stall: bool = False


class Axis:
    """One axis: parameters in ``ap`` (the module's RAM copy), state here."""

    def __init__(
        self,
        ap: dict[int, int],
        mech: Mechanics | None = None,
        switches: Switches | None = None,
        end_switch_polarity: int = 0,
    ) -> None:
        self.ap = ap
        self.mech = mech or Mechanics()
        self.sw = switches or Switches()
        self.faults = Faults()
        #: global parameter 79 (§10.1): inverts the stop switch inputs
        self.polarity = end_switch_polarity
        self.t_ns = 0
        # ramp generator, in the host's position unit (µsteps or encoder steps)
        self.mode = POSITION
        self.pos = 0.0
        self.vel = 0.0
        self.target = 0
        self.vtarget = 0
        self.decelerating = False
        self.hard_stopped = False
        # rotor, in motor microsteps
        self.rotor = 0.0
        self.rotor_v = 0.0
        #: commanded rotor angle in open loop, motor microsteps
        self.cmd = 0.0
        self.enc_offset = 0
        self.enc_frozen: int | None = None
        # closed loop
        self.closed = False
        self.cl_ready = False
        self.cl_init_ns = 0
        self.enc_init = 0
        self.enc_init_ns = 0
        self.delta = 0.0
        self.cl_integral = 0.0
        self.csf = 0
        self.csf_target = 0
        self.csf_timer = 0.0
        self.in_window_s = 0.0
        self.torque_current = 0.0
        # status
        self.reached = False
        self.deviation = False
        self.freewheel_on_deviation = False
        self.standstill_s = 0.0
        self.i2t = 0.0
        self.i2t_flag = False
        self.i2t_over = False
        self.sg = 0
        self.cs_actual = 31
        self.cs_timer = 0.0
        self.stall_flag = False
        self.current_ma = 0.0
        self.measured_v = 0.0
        self._enc_last = 0
        self._enc_acc_s = 0.0
        self._enc_acc_d = 0
        self._switch_last = (False, False, False)
        #: edges since the module last looked: "reached", "stall", "deviation",
        #: "left+", "left-", "right+", "right-"
        self.events: list[str] = []
        self.settled = False
        self.home_search: RefSearchLike | None = None

    # ----------------------------------------------------------------- units

    @property
    def usteps(self) -> int:
        """Microsteps per full step of the ramp's unit in open loop (axis parameter 140)."""
        return 1 << self.ap[140]

    @property
    def fullsteps(self) -> int:
        return max(1, self.ap[202])

    @property
    def enc_res(self) -> int:
        return max(1, self.ap[210])

    def unit_to_rotor(self) -> float:
        """Motor microsteps per host position unit."""
        if self.closed:
            return 256 * self.fullsteps / self.enc_res
        return 256 / self.usteps

    def pos_per_pulse(self) -> float:
        """Host position units per pulse (the microstep of axis parameter 140): speeds and
        accelerations count pulses in both loops (§5.7.1, §6.1, decision T7), positions
        count encoder steps in closed loop (§8.4)."""
        if self.closed:
            return self.enc_res / (self.usteps * self.fullsteps)
        return 1.0

    def encoder(self) -> int:
        """The encoder counter (axis parameter 209)."""
        if self.enc_frozen is not None:
            return self.enc_frozen
        return math.floor(self.rotor * self.enc_res / (256 * self.fullsteps)) + self.enc_offset

    def actual(self) -> int:
        """Axis parameter 1: the ramp's step counter in open loop, the encoder in closed
        loop (§8.4)."""
        if self.closed:
            return to_signed(self.encoder())
        return to_signed(round(self.pos))

    # ----------------------------------------------------------------- commands

    def _motion_command(self) -> None:
        self.settled = False
        self.hard_stopped = False
        if self.deviation:  # §8.1, axis parameter 212: the next command drives again
            self.deviation = False
            self.freewheel_on_deviation = False
            if self.closed:
                self.pos = float(self.encoder())
        self.stall_flag = False

    def rotate(self, velocity: int) -> None:
        """ROR/ROL (§5.7.1, §5.7.2): velocity mode, target speed = ``velocity``."""
        self._motion_command()
        self.mode = VELOCITY
        self.vtarget = velocity
        self.reached = False

    def stop(self) -> None:
        """MST (§5.7.3): target speed 0 in velocity mode."""
        self._motion_command()
        if self.mode == TORQUE:
            self.torque_current = 0.0
        self.mode = VELOCITY
        self.vtarget = 0

    def hard_stop(self) -> None:
        """Stop at once (end switch without soft stop, deviation, stall)."""
        self.vel = 0.0
        self.vtarget = 0
        self.target = round(self.pos)
        self.hard_stopped = True
        if self.mode == TORQUE:
            self.torque_current = 0.0
        self.mode = VELOCITY

    def move_to(self, position: int) -> None:
        """MVP (§5.7.4): position mode toward ``position``."""
        self._motion_command()
        self.mode = POSITION
        self.target = position
        self.reached = False
        self.in_window_s = 0.0

    def set_torque(self, current_ma: int) -> None:
        """SAP 14 (§8.7): torque mode with this target current."""
        self._motion_command()
        self.mode = TORQUE
        self.ap[14] = current_ma
        if self.torque_current == 0.0:
            start = self.ap[141]
            self.torque_current = math.copysign(min(start, abs(current_ma)), current_ma)

    def set_actual(self, value: int) -> None:
        """SAP 1: set the position counter; the target moves along at rest (decision T9)."""
        shift = value - self.actual()
        if self.closed:
            self.enc_offset += shift
        self.pos += shift
        at_rest = self.mode == POSITION and self.vel == 0.0 and self.reached
        if at_rest or self.mode != POSITION:
            self.target += shift
        self.settled = False

    def set_encoder(self, value: int) -> None:
        """SAP 209: load the encoder counter."""
        shift = value - self.encoder()
        self.enc_offset += shift
        if self.closed:
            self.pos += shift
            self.target += shift

    def set_closed_loop(self, on: bool) -> None:
        """SAP 129 (§8.1): switching to closed loop initialises it; the ramp changes unit."""
        if on == self.closed:
            return
        scale_old = self.unit_to_rotor()
        self.closed = on
        scale_new = self.unit_to_rotor()
        if on:
            self.pos = float(self.encoder())
            self.target = round(self.target * scale_old / scale_new) if self.mode == POSITION else 0
            if self.mode == POSITION and self.reached:
                self.target = self.encoder()
            self.cl_ready = False
            self.cl_init_ns = self.t_ns
        else:
            # the host's coordinates go on: the encoder's position in microsteps (§8.4)
            self.pos = float(round(self.encoder() * scale_old / scale_new))
            self.cmd = self.rotor
            self.target = round(self.target * scale_old / scale_new)
            if self.mode == POSITION and self.reached:
                self.target = round(self.pos)
            self.cl_ready = False
            if self.mode == TORQUE:
                self.mode = VELOCITY
                self.vtarget = 0
        self.settled = False  # speeds stay in pulses per second (T7)

    def start_encoder_init(self) -> None:
        """SAP 132, 1 (§6): the encoder initialisation runs for one second."""
        self.enc_init = 1
        self.enc_init_ns = self.t_ns
        self.settled = False

    # ----------------------------------------------------------------- reading

    def switch(self, name: str) -> bool:
        """The logical state of a switch (polarity of global parameter 79 applied to the
        stop switches, §10.1)."""
        raw = self.sw.raw(name, self.rotor)
        if name != "home" and self.polarity:
            raw = not raw
        return raw

    def run_current(self) -> float:
        """The RMS current the driver is set to now, mA (axis parameters 6, 7, 200, 204,
        214, 179; coolStep 180)."""
        ap = self.ap
        if self.faults.overtemperature or self.faults.short or self.freewheel_on_deviation:
            return 0.0
        full = I_RMS_MAX_MA if ap[179] == 0 else I_RMS_MAX_MA / 2
        if self.closed:
            if self.mode == TORQUE:
                return min(abs(self.torque_current), full * ap[6] / 255)
            scale = self.csf / 255 if ap[122] else 1.0
            return full * ap[6] / 255 * scale
        moving = self.vel != 0.0 or (self.mode == VELOCITY and self.vtarget != 0)
        if not moving:
            if ap[204] and self.standstill_s * 1000 >= ap[204]:
                return 0.0
            if self.standstill_s >= ap[214] * 0.01:
                return full * ap[7] / 255
        cs = ap[6]
        if ap[200] and self._accelerating():
            cs = ap[200]
        if ap[183] and abs(self.vel) < ap[182]:
            cs = ap[183]
        return full * cs / 255 * (self.cs_actual + 1) / 32

    def _accelerating(self) -> bool:
        if self.mode == VELOCITY:
            return abs(self.vel - self.vtarget) > 0.5
        return self.mode == POSITION and self.vel != 0.0 and abs(self.vel) < self.ap[4]

    def status_word(self) -> int:
        """Axis parameter 18 (§6)."""
        w = 0
        if self.reached and self.mode == POSITION:
            w |= SW_TARGET
        if self.velocity_reached():
            w |= SW_VELOCITY
        if self.closed:
            w |= SW_CLOSED
        w |= (SW_POSITION, SW_VELMODE, SW_TORQUE)[self.mode]
        if self.switch("home"):
            w |= SW_HOME
        if self.switch("left"):
            w |= SW_LEFT
        if self.switch("right"):
            w |= SW_RIGHT
        if self.faults.undervoltage:
            w |= SW_UNDERV
        if self.faults.overtemperature:
            w |= SW_OVERT
        if self.closed and self.mode == POSITION and self.reached:
            w |= SW_HOLD
        if self.i2t_flag:
            w |= SW_I2T
        return w

    def velocity_reached(self) -> bool:
        """Axis parameter 16 (§8.6): the measured speed inside the window of 17."""
        want = self.vtarget if self.mode == VELOCITY else self.target_speed()
        v = self.measured_v if self.closed else self.vel
        return abs(v - want) <= self.ap[17]

    def target_speed(self) -> int:
        """Axis parameter 2: in position mode ±max speed while accelerating or cruising,
        0 while decelerating and at rest (§6)."""
        if self.mode == VELOCITY:
            return self.vtarget
        if self.mode == TORQUE or self.vel == 0.0 or self.decelerating:
            return 0
        return self.ap[4] if self.vel > 0 else -self.ap[4]

    def driver_errors(self) -> int:
        """Axis parameter 208 (§6)."""
        e = 0
        if self.stall_flag or (self.sg == 0 and self.vel != 0.0 and not self.closed):
            e |= DE_STALL
        if self.faults.overtemperature:
            e |= DE_OT | DE_OTPW
        if self.faults.short:
            e |= DE_S2GA | DE_S2GB
        if self.vel == 0.0 and self.standstill_s > 0.1:
            e |= DE_STST
        return e

    def position_error(self) -> int:
        """Axis parameter 237: virtual ramp position minus the measured position, in the
        host's unit (§8.10)."""
        if self.closed:
            return to_signed(round(self.pos) - self.encoder())
        measured = (self.encoder() - self.enc_offset) * 256 * self.fullsteps / self.enc_res
        return to_signed(round(self.cmd - measured) * self.usteps // 256)

    def gamma(self) -> int:
        """Axis parameter 230 (§8.9): the field weakening between speeds 108 and 109."""
        lo, hi = self.ap[108], self.ap[109]
        v = abs(self.measured_v)
        if v <= lo or hi <= lo:
            return 0 if v <= lo else 255
        return min(255, round(255 * (v - lo) / (hi - lo)))

    def phase_currents(self) -> tuple[int, int]:
        """Axis parameters 151/152: peak phase currents, mA."""
        amp = self.current_ma * math.sqrt(2)
        angle = self._commutation()
        return round(amp * math.cos(angle)), round(amp * math.sin(angle))

    def _commutation(self) -> float:
        if self.closed:
            measured = (self.encoder() - self.enc_offset) * 256 * self.fullsteps / self.enc_res
            return measured * ELEC_PER_USTEP + self.delta
        return self.cmd * ELEC_PER_USTEP

    # ----------------------------------------------------------------- time

    def advance_to(self, t_ns: int) -> None:
        """Run the physics up to ``t_ns`` in steps of :data:`DT_NS`."""
        while self.t_ns + DT_NS <= t_ns:
            if self.settled and self._idle_skip(t_ns):
                continue
            self.step()

    def _idle_skip(self, t_ns: int) -> bool:
        """At rest with nothing to change: jump ahead to the next timed change in whole
        steps (standby current, freewheeling, I²t decay are exact)."""
        ap = self.ap
        horizon = t_ns
        marks = [ap[214] * 0.01, (ap[204] / 1000) if ap[204] else None]
        for mark in marks:
            if mark is not None and self.standstill_s < mark:
                horizon = min(horizon, self.t_ns + int((mark - self.standstill_s) * 1e9) + DT_NS)
        n = (horizon - self.t_ns) // DT_NS
        if n <= 1:
            return False
        n -= 1
        span = n * DT
        self.t_ns += n * DT_NS
        self.standstill_s += span
        self._i2t_update(span)
        self._enc_acc_s += span
        return True

    def step(self) -> None:
        """One physics step."""
        self.t_ns += DT_NS
        before = (self.pos, self.vel, self.rotor, self.rotor_v, self.current_ma)
        self._ramp()
        self._mechanics()
        self._supervise()
        after = (self.pos, self.vel, self.rotor, self.rotor_v, self.current_ma)
        busy = self.enc_init == 1 or (self.closed and not self.cl_ready)
        busy = busy or self.home_search is not None or (self.closed and not self.reached)
        # closed loop at rest: the regulation works on until the encoder shows the target,
        # or its integral can give no more (a blocked rotor, a lost encoder)
        busy = busy or (
            self.closed
            and self.mode == POSITION
            and self.encoder() != self.target
            and abs(self.cl_integral) < math.pi / 2
        )
        self.settled = after == before and not busy and self.rotor_v == 0.0

    def _ramp(self) -> None:
        """The ramp generator (§5.7.1-5.7.4, §8.4): trapezoidal toward the target position
        or speed, landing exactly on the target position."""
        ap = self.ap
        acc = ap[5] * DT
        v0 = self.vel
        if self.home_search is not None:
            self.home_search.tick(self)
        if self.mode == TORQUE or self.freewheel_on_deviation:
            self.vel = 0.0
            return
        if self.mode == VELOCITY:
            self.decelerating = False
            want = float(self.vtarget)
            if self.vel < want:
                self.vel = min(want, self.vel + acc)
            elif self.vel > want:
                self.vel = max(want, self.vel - acc)
            self._advance_pos((v0 + self.vel) / 2 * DT)
            return
        if self.target == self.pos and self.vel == 0.0:
            self.decelerating = False
            return
        # the way to go in pulses: speeds and acceleration are pulses per second (T7)
        per_pulse = self.pos_per_pulse()
        remaining = (self.target - self.pos) / per_pulse
        vmax = float(ap[4])
        vstop = float(min(ap[130], ap[4]))
        direction = 1.0 if remaining > 0 else -1.0
        speed = self.vel * direction  # along the way to the target
        if speed < 0:  # moving away: brake first
            speed = min(0.0, speed + acc)
            self.vel = speed * direction
            self.decelerating = True
            self._advance_pos((v0 + self.vel) / 2 * DT)
            return
        reach = math.sqrt(vstop * vstop + 2 * ap[5] * abs(remaining))
        if speed > vmax:
            new = max(vmax, speed - acc)
        else:
            new = min(vmax, max(speed + acc, vstop) if speed < vstop else speed + acc)
        self.decelerating = new > reach or speed > vmax
        new = min(new, reach)
        step = (speed + new) / 2 * DT
        if step >= abs(remaining) or new <= 0.0:
            self._advance_pos(remaining)
            self.pos = float(self.target)
            self.vel = 0.0
            self.decelerating = False
            return
        self.vel = new * direction
        self._advance_pos(step * direction)

    def _advance_pos(self, pulses: float) -> None:
        """The ramp moves on by ``pulses`` (microsteps of axis parameter 140)."""
        if self.closed:
            self.pos += pulses * self.pos_per_pulse()
        else:
            self.pos += pulses
            self.cmd += pulses * 256 / self.usteps

    def _mechanics(self) -> None:
        """The rotor: J dω/dt = T_motor - friction - load (semi-implicit Euler); the load
        and the Coulomb friction hold the rotor at rest up to their sum (T32)."""
        m = self.mech
        self.current_ma = self.run_current()
        amps = self.current_ma / 1000
        rotor_elec = self.rotor * ELEC_PER_USTEP
        per_rad = 256 * self.fullsteps / (2 * math.pi)
        omega = self.rotor_v / per_rad
        if self.closed:
            torque = self._closed_loop_torque(amps)
            field = omega  # the commutation follows the encoder
        else:
            torque = m.torque_per_amp * amps * math.sin(self.cmd * ELEC_PER_USTEP - rotor_elec)
            field = self.vel * 256 / self.usteps / per_rad
        torque *= self._current_reach(amps, omega, field)
        inertia = m.rotor_inertia + m.load_inertia
        net = torque - m.viscous * omega
        holding = m.friction + abs(m.load)
        if self.faults.stall:
            self.rotor_v = 0.0
            return
        if omega == 0.0 and abs(net) <= holding:
            self.rotor_v = 0.0
        else:
            sign = 1.0 if (omega > 0 or (omega == 0.0 and net > 0)) else -1.0
            alpha = (net - sign * holding) / inertia
            new = omega + alpha * DT
            if omega != 0.0 and (new > 0) != (omega > 0):
                new = 0.0  # friction and load stop the rotor, they do not reverse it
            self.rotor_v = new * per_rad
            self.rotor += self.rotor_v * DT

    def _current_reach(self, amps: float, omega: float, field: float) -> float:
        """The share of the set current the chopper can drive (0-1), decision T31.

        Per phase the supply must cover the resistive and inductive drops and the back
        EMF; with the current in phase with the back EMF (the torque-forming part):
        V² = (R I + E)² + (X I)², E = k_e ω, X = p ω_field L, p pole pairs (50 for 200
        full steps), k_e = k_t in SI units. Solved for the peak current I, it is V/R at
        rest, falls once the inductance and the back EMF take the voltage (the corner
        speed) and ends where E reaches V: the pull-out torque falls with speed.

        ``omega`` is the rotor's speed, ``field`` the speed of the current vector (the
        ramp's in open loop), both mechanical rad/s."""
        if amps == 0.0:
            return 1.0
        m = self.mech
        k_e = m.torque_per_amp / math.sqrt(2)  # V s/rad per phase, peak
        e = k_e * abs(omega)
        v = m.supply_v
        if e >= v:
            return 0.0
        r = m.resistance
        x = abs(field) * self.fullsteps / 4 * m.inductance
        z2 = r * r + x * x
        if z2 <= 0.0:
            return 1.0
        peak = (math.sqrt(r * r * e * e - z2 * (e * e - v * v)) - r * e) / z2
        return min(1.0, peak / (amps * math.sqrt(2)))

    def _closed_loop_torque(self, amps: float) -> float:
        """§8.2-8.8: commutation from the encoder with an advance angle from the position
        error; the current scaled by the error."""
        ap = self.ap
        m = self.mech
        if self.mode == TORQUE:
            slope = ap[20] * DT
            want = float(ap[14])
            if self.torque_current < want:
                self.torque_current = min(want, self.torque_current + slope)
            else:
                self.torque_current = max(want, self.torque_current - slope)
            self.delta = math.copysign(math.pi / 2, self.torque_current or 1.0)
            return (
                m.torque_per_amp
                * self.current_ma
                / 1000
                * math.copysign(1.0, self.torque_current)
                * (self.torque_current != 0.0)
            )
        if not self.cl_ready:
            return 0.0
        enc_to_rotor = 256 * self.fullsteps / self.enc_res
        # the regulation compares ramp and encoder in the host's coordinates (both carry
        # what SAP 1/209 and the reference search set); the commutation needs the rotor's
        # own angle, the encoder without that offset
        enc = self.encoder()
        measured = (enc - self.enc_offset) * enc_to_rotor
        err = (self.pos - enc) * enc_to_rotor * ELEC_PER_USTEP  # electrical radians
        slip = (self.rotor_v - self.vel * 256 / self.usteps) * ELEC_PER_USTEP
        gain = ap[136] / 10
        damp = CL_DAMPING * (1.0 + ap[137] / 100)
        # PI on the position error (the integral holds a load without a standing error),
        # D on the speed difference; the advance angle is at most one full step (§8.2)
        self.cl_integral += CL_INTEGRAL * gain * err * DT
        self.cl_integral = max(-math.pi / 2, min(math.pi / 2, self.cl_integral))
        delta = gain * err + self.cl_integral - damp * slip
        self.delta = max(-math.pi / 2, min(math.pi / 2, delta))
        self._current_scale(abs(round(self.pos) - enc))
        rotor_elec = self.rotor * ELEC_PER_USTEP
        angle = measured * ELEC_PER_USTEP + self.delta - rotor_elec
        return m.torque_per_amp * amps * math.sin(angle)

    def _current_scale(self, err: int) -> None:
        """§8.8: target current scale from the position error (113, 114, 116, 117), the
        actual one following with steps 118/119 every 120/121 ms."""
        ap = self.ap
        e = err * ap[136] / 10 if ap[115] else err
        lo, hi = ap[116], ap[117]
        if e <= lo:
            target = ap[113]
        elif e >= hi or hi <= lo:
            target = ap[114]
        else:
            target = round(ap[113] + (ap[114] - ap[113]) * (e - lo) / (hi - lo))
        # the load: an advance angle toward 90 degrees asks for more current (decision T8)
        by_load = round(ap[113] + (ap[114] - ap[113]) * abs(self.delta) / (math.pi / 2))
        target = max(target, by_load)
        self.csf_target = target
        if self.csf == target:
            self.csf_timer = 0.0
            return
        up = target > self.csf
        timeout = (ap[120] if up else ap[121]) / 1000
        if timeout == 0:
            self.csf = target
            return
        self.csf_timer += DT
        if self.csf_timer >= timeout:
            self.csf_timer = 0.0
            step = ap[118] if up else ap[119]
            step = max(1, step)
            self.csf = min(target, self.csf + step) if up else max(target, self.csf - step)

    def _supervise(self) -> None:
        """Flags and protections after each step: target reached, end switches, encoder
        deviation, stallGuard2, coolStep, I²t, closed-loop and encoder init."""
        ap = self.ap
        moving = self.vel != 0.0
        self.standstill_s = 0.0 if moving else self.standstill_s + DT
        self._measure_speed()
        self._inits()
        self._target_flag()
        self._end_switches()
        self._deviation()
        self._stallguard()
        self._i2t_update(DT)
        del ap

    def _measure_speed(self) -> None:
        """Axis parameter 131: encoder speed over 10 ms windows, in pps (T7)."""
        self._enc_acc_s += DT
        if self._enc_acc_s >= 0.01:
            enc = self.encoder()
            d = enc - self._enc_last
            self._enc_last = enc
            per_s = d / self._enc_acc_s * self.usteps * self.fullsteps / self.enc_res
            self.measured_v = per_s
            self._enc_acc_s = 0.0

    def _inits(self) -> None:
        if self.enc_init == 1 and self.t_ns - self.enc_init_ns >= 1_000_000_000:
            ok = not self.faults.encoder_loss and self.enc_res > 2 * self.fullsteps
            self.enc_init = 2 if ok else 3
        due = self.closed and not self.cl_ready and self.t_ns - self.cl_init_ns >= 100_000_000
        if due and not self.faults.encoder_loss and self.enc_res > 2 * self.fullsteps:
            self.cl_ready = True
            self.pos = float(self.encoder())
            if self.mode == POSITION and self.reached:
                self.target = self.encoder()

    def _target_flag(self) -> None:
        """Axis parameter 8: open loop when the ramp stands on the target; closed loop when
        the encoder stays inside the window of 134 for the time of 135 (§8.5)."""
        was = self.reached
        if self.mode != POSITION:
            self.reached = False
            return
        if self.closed:
            on_ramp = self.pos == self.target and self.vel == 0.0
            inside = abs(self.target - self.encoder()) <= self.ap[134]
            self.in_window_s = self.in_window_s + DT if (on_ramp and inside) else 0.0
            self.reached = self.in_window_s * 10_000 >= self.ap[135]
        else:
            self.reached = self.pos == self.target and self.vel == 0.0
        if self.reached and not was:
            self.events.append("reached")

    def _end_switches(self) -> None:
        """§9, axis parameters 12/13/149: a stop switch stops motion toward it."""
        left, right, home = self.switch("left"), self.switch("right"), self.switch("home")
        last = self._switch_last
        for i, (name, now) in enumerate((("left", left), ("right", right), ("home", home))):
            if now != last[i]:
                self.events.append(f"{name}{'+' if now else '-'}")
        self._switch_last = (left, right, home)
        if self.home_search is not None:
            return
        toward_left = self.vel < 0 or (self.mode == VELOCITY and self.vtarget < 0)
        toward_right = self.vel > 0 or (self.mode == VELOCITY and self.vtarget > 0)
        hit = (left and toward_left and not self.ap[13]) or (
            right and toward_right and not self.ap[12]
        )
        if not hit:
            return
        if self.ap[149]:  # soft stop: decelerate with the ramp
            if self.mode != VELOCITY or self.vtarget != 0:
                self.mode = VELOCITY
                self.vtarget = 0
        else:
            self.hard_stop()

    def _deviation(self) -> None:
        """Axis parameter 212 (§8.1): stop (or switch off, when negative) beyond the
        allowed difference of commanded and encoder position; flag 207."""
        limit = self.ap[212]
        if limit == 0 or self.deviation:
            return
        if self.closed and not self.cl_ready:
            return
        if abs(self.position_error()) > abs(limit):
            self.deviation = True
            self.events.append("deviation")
            if limit < 0:
                self.freewheel_on_deviation = True
            if self.closed:
                self.pos = float(self.encoder())
            else:
                per_unit = 256 / self.usteps
                measured = (self.encoder() - self.enc_offset) * 256 * self.fullsteps
                self.cmd = measured / self.enc_res
                self.pos = round(self.cmd / per_unit)
            self.hard_stop()

    def _stallguard(self) -> None:
        """§7: the load value falls with the load angle; stop on stall (181); coolStep
        (168-172, 180, 182) adapts the current to it."""
        ap = self.ap
        moving = abs(self.rotor_v) > 1.0 or self.vel != 0.0
        if not moving or self.current_ma == 0.0:
            self.sg = 0
            return
        if self.closed:
            angle = self.delta
        else:
            angle = self.cmd * ELEC_PER_USTEP - self.rotor * ELEC_PER_USTEP
        load = min(1.0, abs(math.sin(angle)))
        if self.faults.stall:
            load = 1.0
        sgt = to_signed(ap[174] & 0xFFFFFFFF)
        self.sg = max(0, min(1023, round(1023 * (1.0 - load)) + 16 * sgt))
        if self.sg == 0 and ap[181] and abs(self.vel) >= ap[181]:
            if not self.stall_flag:
                self.stall_flag = True
                self.events.append("stall")
            self.hard_stop()
        self._coolstep()

    def _coolstep(self) -> None:
        ap = self.ap
        self.cs_timer += DT
        if self.cs_timer < 0.001:
            return
        self.cs_timer = 0.0
        if ap[172] == 0 or abs(self.vel) < ap[182]:
            self.cs_actual = 31
            return
        lower = ap[172] * 32
        upper = (ap[172] + ap[170] + 1) * 32
        floor = 15 if ap[168] == 0 else 7
        if self.sg < lower:
            self.cs_actual = min(31, self.cs_actual + (1, 2, 4, 8)[ap[171]])
        elif self.sg > upper:
            self.cs_actual = max(floor, self.cs_actual - 1)

    def _i2t_update(self, span: float) -> None:
        """Axis parameters 25-29: the mean of I² (mA², /10) over the thermal time constant
        of 25; above the limit of 26 the counter 28 counts and the flag is set (T13)."""
        tau = self.ap[25] / 1000
        sq = self.current_ma * self.current_ma / 10
        if tau <= 0:
            self.i2t = sq
        else:
            self.i2t = sq + (self.i2t - sq) * math.exp(-span / tau)
        over = self.i2t > self.ap[26]
        if over and not self.i2t_over:
            self.ap[28] = min(self.ap[28] + 1, 0xFFFFFFFF)
            self.i2t_flag = True
        self.i2t_over = over


class RefSearchLike:
    """What the axis needs of a running reference search (ecatsim/tmcl/refsearch.py)."""

    def tick(self, axis: Axis) -> None:
        raise NotImplementedError
