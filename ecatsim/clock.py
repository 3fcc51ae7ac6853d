"""The one place that reads the OS clock. Everything else gets a Clock injected.

Time is injected, so tests and the simulated devices are deterministic.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """A monotonic nanosecond clock."""

    def now_ns(self) -> int: ...


class MonotonicClock:
    """The OS monotonic clock."""

    __slots__ = ()

    def now_ns(self) -> int:
        return time.monotonic_ns()


class ManualClock:
    """A clock that only moves when told to; for tests."""

    __slots__ = ("t",)

    def __init__(self, start_ns: int = 0) -> None:
        self.t = start_ns

    def now_ns(self) -> int:
        return self.t

    def advance(self, dt_ns: int) -> None:
        self.t += dt_ns
