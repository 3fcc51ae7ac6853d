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
    """Drive ``direction`` at the search (fast) or switch (slow) speed until ``switch`` is
    ``level``; ``note`` keeps the position; ``bounce`` reverses at that stop switch."""

    direction: int
    fast: bool
    switch: str
    level: bool
    note: bool = False
    bounce: str | None = None


def _calibrate(switch: str, toward: int) -> list[Leg]:
    """Find ``switch`` driving ``toward``, leave it slowly, re-enter it slowly: the two
    switching points (§9 hints)."""
    return [
        Leg(toward, True, switch, True),
        Leg(-toward, False, switch, False, note=True),
        Leg(toward, False, switch, True, note=True),
    ]


def _home(toward: int, bounce: str | None) -> list[Leg]:
    """Find the home switch, then both of its edges slowly: its middle is the reference."""
    return [
        Leg(toward, True, "home", True, bounce=bounce),
        Leg(toward, False, "home", False, note=True),
        Leg(-toward, False, "home", True),
        Leg(-toward, False, "home", False, note=True),
    ]


def legs_for(mode: int) -> list[Leg]:
    """The legs of a search mode 1-8 (§9.1.1)."""
    m = mode & 0x7F
    if m in (1, 4):
        return _calibrate("left", -1)
    if m == 2:
        return [Leg(1, True, "right", True, note=True), *_calibrate("left", -1)]
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
        self.leg = 0
        self.notes: list[float] = []
        self.started = False
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
        if not self.started:
            self.started = True
            self._drive(axis, self.legs[0])
            return
        leg = self.legs[self.leg]
        if leg.bounce is not None and self._level(axis, leg.bounce):
            self.legs[self.leg] = Leg(-leg.direction, True, leg.switch, leg.level, leg.note)
            self.legs = [
                Leg(-x.direction, x.fast, x.switch, x.level, x.note) if i > self.leg else x
                for i, x in enumerate(self.legs)
            ]
            self._drive(axis, self.legs[self.leg])
            return
        if self._level(axis, leg.switch) != leg.level:
            return
        if leg.note:
            self.notes.append(axis.pos)
        self.leg += 1
        if self.leg < len(self.legs):
            axis.vel = 0.0  # the switch stops the search at once (§9)
            self._drive(axis, self.legs[self.leg])
            return
        self._finish(axis)

    def _finish(self, axis: Axis) -> None:
        ref = (self.notes[-1] + self.notes[-2]) / 2
        if len(self.notes) >= 3:
            self.distance = round(abs(self.notes[0] - ref))
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
