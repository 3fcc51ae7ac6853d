"""The reference search state machine (RFS, axis parameter 193).

A search is a list of legs. Each leg drives at a speed in one direction until a switch
reaches a level, and may note the position where that happened. At the end the reference
point (the middle of the two switching points of the last switch, §9) becomes position 0
and the axis moves there.

Ref: TMCM-1311 TMCL firmware manual §5.7.13 (RFS), §9 (hints), §9.1.1 (modes 1-8, +128).
"""

from __future__ import annotations

from dataclasses import dataclass

from ecatsim.tmcl.motor import POSITION, Axis, RefSearchLike


@dataclass(frozen=True, slots=True)
class Leg:
    """Drive ``direction`` at the search (fast) or switch (slow) speed until ``switch`` has
    shown each level of ``levels`` in turn (a level already there counts at once); the
    levels marked in ``note`` keep the position where they came. ``bounce`` reverses the
    search at that stop switch. After each leg the axis stops with its ramp."""

    direction: int
    fast: bool
    switch: str
    levels: tuple[bool, ...]
    note: tuple[bool, ...] = ()
    bounce: str | None = None

    def reversed(self) -> Leg:
        return Leg(-self.direction, self.fast, self.switch, self.levels, self.note)


def _calibrate(switch: str, toward: int) -> list[Leg]:
    """Find a stop switch driving ``toward``, leave it slowly, re-enter it slowly: the two
    switching points (§9 hints)."""
    return [
        Leg(toward, True, switch, (True,)),
        Leg(-toward, False, switch, (False,), (True,)),
        Leg(toward, False, switch, (True,), (True,)),
    ]


def _home(toward: int, bounce: str | None) -> list[Leg]:
    """Find the home switch, back out of it slowly, cross it slowly: its middle is the
    reference."""
    return [
        Leg(toward, True, "home", (True,), bounce=bounce),
        Leg(-toward, False, "home", (True, False)),
        Leg(toward, False, "home", (True, False), (True, True)),
    ]


def _home_edge(toward: int, bounce: str | None) -> list[Leg]:
    """With the inverted home switch (+128) the home level is active everywhere but over
    the switch, an open-ended range: the search drives until it becomes active (an edge,
    not a level it starts on), then calibrates that switching point as §9's hints say:
    released slowly, re-entered slowly, the reference in the middle (decision T27)."""
    return [
        Leg(toward, True, "home", (False, True), bounce=bounce),
        Leg(-toward, False, "home", (False,), (True,)),
        Leg(toward, False, "home", (True,), (True,)),
    ]


def legs_for(mode: int) -> list[Leg]:
    """The legs of a search mode 1-8, +128 (§9.1.1)."""
    m = mode & 0x7F
    if mode & 0x80 and 5 <= m <= 8:
        toward = -1 if m in (5, 8) else 1
        return _home_edge(toward, {5: "left", 6: "right"}.get(m))
    if m in (1, 4):
        return _calibrate("left", -1)
    if m == 2:
        return [Leg(1, True, "right", (True,), (True,)), *_calibrate("left", -1)]
    if m == 3:
        return [*_calibrate("right", 1), *_calibrate("left", -1)]
    if m == 5:
        return _home(-1, "left")
    if m == 6:
        return _home(1, "right")
    if m == 7:
        return _home(1, None)
    return _home(-1, None)


class RefSearch(RefSearchLike):
    """One running search on an axis (driven from :meth:`Axis._ramp` every step)."""

    def __init__(self, mode: int) -> None:
        self.mode = mode
        self.legs = legs_for(mode)
        self.leg = -1
        self.step = 0
        self.notes: list[float] = []
        self.stopping = True
        self.finishing = False
        self.done = False
        #: axis parameter 196 (modes 2 and 3): distance between the end switches
        self.distance: int | None = None

    def _level(self, axis: Axis, name: str) -> bool:
        level = axis.switch(name)
        if name == "home" and self.mode & 0x80:
            level = not level
        return level

    def _drive(self, axis: Axis, leg: Leg) -> None:
        speed = axis.ap[194] if leg.fast else axis.ap[195]
        axis.mode = 1
        axis.vtarget = leg.direction * max(1, speed)

    def tick(self, axis: Axis) -> None:
        if self.finishing:
            if axis.mode == POSITION and axis.pos == axis.target and axis.vel == 0.0:
                self.done = True
                axis.home_search = None
            return
        if self.stopping:  # the ramp stops the axis between legs
            axis.mode = 1
            axis.vtarget = 0
            if axis.vel != 0.0 or abs(axis.rotor_v) > 1.0:
                return
            self.stopping = False
            self.leg += 1
            self.step = 0
            if self.leg == len(self.legs):
                self._finish(axis)
                return
            self._drive(axis, self.legs[self.leg])
            return
        leg = self.legs[self.leg]
        if leg.bounce is not None and self._level(axis, leg.bounce):
            self.legs = [x.reversed() if i >= self.leg else x for i, x in enumerate(self.legs)]
            self.legs[self.leg] = Leg(-leg.direction, True, leg.switch, leg.levels)
            self.step = 0
            self._drive(axis, self.legs[self.leg])
            return
        ahead = "right" if leg.direction > 0 else "left"
        if (self.mode & 0x7F) <= 6 and leg.switch != ahead and self._level(axis, ahead):
            # a stop switch the search does not look for ends it there (decision T27);
            # modes 7 and 8 ignore the end switches (§9.1.1)
            self.abort(axis)
            return
        while (
            self.step < len(leg.levels) and self._level(axis, leg.switch) == leg.levels[self.step]
        ):
            if self.step < len(leg.note) and leg.note[self.step]:
                # where the rotor is: the encoder in closed loop, the ramp in open loop
                self.notes.append(float(axis.encoder()) if axis.closed else axis.pos)
            self.step += 1
        if self.step == len(leg.levels):
            self.stopping = True

    def _finish(self, axis: Axis) -> None:
        ref = (self.notes[-1] + self.notes[-2]) / 2
        if len(self.notes) >= 3:
            self.distance = round(abs(self.notes[0] - ref))
            axis.ap[196] = self.distance
        shift = -round(ref)
        axis.vel = 0.0
        axis.pos += shift
        if axis.closed:
            axis.enc_offset += shift
        axis.mode = POSITION
        axis.target = 0
        axis.reached = False
        self.finishing = True

    def abort(self, axis: Axis) -> None:
        """RFS STOP: the axis decelerates, the search ends."""
        axis.home_search = None
        axis.mode = 1
        axis.vtarget = 0
        self.done = True
