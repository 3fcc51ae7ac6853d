"""The TMC211 ramp generator and position controller, and the motor it drives.

Positions are 16-bit two's complement in 1/16 micro-steps, a circle on which the device
takes the shortest way (TMC211 §5.1.7, §7.3 FAQ). The ramp (§5.1.2-5.1.6): start at Vmin,
accelerate with Acc to Vmax, decelerate symmetrically to stop at the target; AccShape = 1
runs at Vmin without a ramp; a target behind the motor is reached through a linear zero
crossing (§5.1.3 Figure 5). The controller updates ActPos every 1024 µs (§7.2 FAQ "ActPos
and ESW are latched ... typ. 1024 µs"), which is the simulation tick.

There is no stall detection (§7.4): the motor model has optional mechanical stops where
the rotor stays while ActPos counts on, and an optional switch range that closes ESW.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

#: the position controller's update period (§7.2 FAQ, §10.4 Table 30 Tsw typ.)
TICK_NS = 1_024_000
TICK_S = TICK_NS / 1e9
SPAN = 65536


def wrap(x: float) -> float:
    """A position on the 16-bit circle, in [-32768, 32768)."""
    return (x + 32768.0) % SPAN - 32768.0


def wrap16(x: int) -> int:
    return (x + 32768) % SPAN - 32768


class Phase(IntEnum):
    """What the ramp generator is doing (for the Motion[2:0] status)."""

    IDLE = 0
    ACC = 1
    DEC = 2
    CONST = 3


@dataclass(slots=True)
class Profile:
    """The velocities of one motion, in units per second (tables.py converts indices)."""

    vmax: float
    vmin: float
    acc: float
    rectangular: bool = False  # AccShape = 1: run at Vmin, no acceleration


class Ramp:
    """Position and velocity of the ramp generator."""

    def __init__(self) -> None:
        #: the position, unquantised, on the 16-bit circle
        self.x = 0.0
        #: signed velocity, units/s
        self.v = 0.0
        self.phase = Phase.IDLE

    def distance(self, target: int) -> float:
        """Signed shortest way from the position to ``target`` (§7.3 FAQ)."""
        return wrap(target - self.x)

    def stop(self) -> None:
        self.v = 0.0
        self.phase = Phase.IDLE

    def step(self, target: int, p: Profile) -> float:
        """One tick towards ``target``; returns the distance moved. Arrives exactly."""
        d = self.distance(target)
        if self.v == 0.0:
            if d == 0.0:
                self.phase = Phase.IDLE
                return 0.0
            rect = p.rectangular or p.vmin >= p.vmax
            self.v = p.vmin if d > 0 else -p.vmin
            self.phase = Phase.CONST if rect else Phase.ACC
        else:
            self._accelerate(d, p)
        dx = self.v * TICK_S
        if d != 0.0 and (dx > 0) == (d > 0) and abs(dx) >= abs(d):
            self.x = float(target)
            self.stop()
            return d
        self.x = wrap(self.x + dx)
        return dx

    def _accelerate(self, d: float, p: Profile) -> None:
        if p.rectangular or p.vmin >= p.vmax:
            self.v = p.vmin if d > 0 else -p.vmin
            self.phase = Phase.CONST
            return
        speed = abs(self.v)
        sign = 1.0 if self.v > 0 else -1.0
        if d == 0.0 or (d > 0) != (self.v > 0):  # target behind: linear zero crossing
            v = self.v - sign * p.acc * TICK_S
            self.phase = Phase.DEC
            if v != 0.0 and (v > 0) != (self.v > 0):  # crossed zero: on the other way
                self.phase = Phase.ACC
            self.v = v
            return
        braking = (speed * speed - p.vmin * p.vmin) / (2 * p.acc) if speed > p.vmin else 0.0
        if abs(d) - speed * TICK_S <= braking or speed > p.vmax:
            speed = max(p.vmin, speed - p.acc * TICK_S)
            self.phase = Phase.DEC
        elif speed < p.vmax:
            speed = min(p.vmax, speed + p.acc * TICK_S)
            self.phase = Phase.CONST if speed >= p.vmax else Phase.ACC
        else:
            self.phase = Phase.CONST
        self.v = sign * speed

    def brake(self, p: Profile) -> bool:
        """One tick of SoftStop: decelerate to Vmin, then stand (§6.11.14). True when
        stopped."""
        speed = abs(self.v)
        if speed <= p.vmin or p.rectangular:
            self.stop()
            return True
        sign = 1.0 if self.v > 0 else -1.0
        speed = max(p.vmin, speed - p.acc * TICK_S)
        self.v = sign * speed
        self.phase = Phase.DEC
        self.x = wrap(self.x + self.v * TICK_S)
        return False

    def motion_status(self, at_target: bool) -> int:
        """Motion[2:0] (§5.2.2; 101 accelerating and 110 decelerating for v < 0,
        decision N8)."""
        if self.v == 0.0:
            return 0b000 if at_target else 0b100
        code = {Phase.ACC: 0b001, Phase.DEC: 0b010, Phase.CONST: 0b011, Phase.IDLE: 0b011}
        return code[self.phase] | (0b100 if self.v < 0 else 0)


class Motor:
    """The motor behind the driver: a rotor that mechanical stops can block, a switch.

    Positions are 1/16 micro-steps from where the rotor started, unbounded."""

    def __init__(
        self,
        rotor: float = 0.0,
        stops: tuple[float, float] | None = None,
        switch: tuple[float, float] | None = None,
    ) -> None:
        self.rotor = rotor
        self.stops = stops
        self.switch = switch
        self.lost_steps = 0.0

    def move(self, dx: float, shaft: int) -> None:
        """The driver stepped ``dx``; Shaft = 1 turns the other way (§7.3 FAQ)."""
        want = self.rotor + (-dx if shaft else dx)
        if self.stops is not None:
            lo, hi = self.stops
            clamped = min(max(want, lo), hi)
            self.lost_steps += abs(want - clamped)
            want = clamped
        self.rotor = want

    def switch_closed(self) -> bool:
        if self.switch is None:
            return False
        lo, hi = self.switch
        return lo <= self.rotor <= hi
