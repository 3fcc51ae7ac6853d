"""The garbage collector's pauses while the daemon serves: how many collections ran and
the longest, for the daemon's ``stopped`` line. A collection holds every frame that comes
meanwhile; the daemon freezes what it built before serving (``gc.freeze``), so what is
collected is what the bring-up and the control socket made since."""

from __future__ import annotations

import gc
import time
from types import TracebackType
from typing import Any


class GcPauses:
    """A ``gc.callbacks`` entry while used as a context manager."""

    def __init__(self) -> None:
        self.count = 0
        self.max_ns = 0
        self._start = 0

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._start = time.perf_counter_ns()
            return
        self.count += 1
        took = time.perf_counter_ns() - self._start
        if took > self.max_ns:
            self.max_ns = took

    def __enter__(self) -> GcPauses:
        gc.callbacks.append(self)
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        gc.callbacks.remove(self)
