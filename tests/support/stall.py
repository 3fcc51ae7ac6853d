"""A watch for host stalls: a process above every other real-time thread of a test that
sleeps 1 ms at a time and reports how late it woke. When it wakes 50 ms late, the host
itself (a virtual machine descheduled, the kernel) stopped everything, master and daemon
alike; a timing test may then repeat its run instead of blaming either."""

from __future__ import annotations

import subprocess
import sys
from types import TracebackType

#: the watch's priority: above the daemon's --rt-priority 40 and a master's 30
WATCH_PRIORITY = 60

_SCRIPT = """
import os, sys, time
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(sys.argv[1])))
worst = 0.0
prev = time.perf_counter()
sys.stdout.write("ready\\n")
sys.stdout.flush()
while True:
    time.sleep(0.001)
    now = time.perf_counter()
    late = now - prev - 0.001
    if late > worst:
        worst = late
        sys.stdout.write(f"{worst:.6f}\\n")
        sys.stdout.flush()
    prev = now
"""


class StallWatch:
    """``with StallWatch() as w: ...`` then ``w.worst_s``: the longest the host kept the
    watch from running (seconds) while the block ran."""

    def __init__(self, priority: int = WATCH_PRIORITY) -> None:
        self.priority = priority
        self.worst_s = 0.0
        self._proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> StallWatch:
        self._proc = subprocess.Popen(
            [sys.executable, "-c", _SCRIPT, str(self.priority)],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self._proc.stdout is not None
        assert self._proc.stdout.readline().strip() == "ready", "the stall watch did not start"
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        proc = self._proc
        assert proc is not None and proc.stdout is not None
        proc.kill()
        out, _ = proc.communicate(timeout=10)
        lines = [ln for ln in out.split() if ln]
        if lines:
            self.worst_s = max(self.worst_s, float(lines[-1]))
        self._proc = None


def stalled(worst_s: float, threshold_s: float = 0.05) -> bool:
    """A stall long enough to explain a master's missed reply or an expired SM watchdog."""
    return worst_s >= threshold_s
