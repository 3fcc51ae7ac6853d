"""A watch for host stalls: on every CPU a process above every other real-time thread of a
test sleeps 1 ms at a time and reports how late it woke. When it wakes milliseconds late,
the host itself (a virtual CPU descheduled, the kernel) stopped everything on that CPU,
master and daemon alike; a timing test may then repeat its run instead of blaming either.
A virtual CPU the host deschedules takes every thread on it along: so one watch per CPU."""

from __future__ import annotations

import os
import subprocess
import sys
from types import TracebackType

#: the watch's priority: above the daemon's --rt-priority 40 and a master's 30
WATCH_PRIORITY = 60
#: a wake this late (ns) is recorded as a stall
RECORDED_NS = 500_000

_SCRIPT = """
import os, sys, time
os.sched_setaffinity(0, {int(sys.argv[2])})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(sys.argv[1])))
prev = time.time_ns()
sys.stdout.write("ready\\n")
sys.stdout.flush()
while True:
    time.sleep(0.001)
    now = time.time_ns()
    if now - prev - 1_000_000 >= int(sys.argv[3]):
        sys.stdout.write(f"{prev + 1_000_000} {now}\\n")
        sys.stdout.flush()
    prev = now
"""


class StallWatch:
    """``with StallWatch() as w: ...`` then ``w.stalls``: when (CLOCK_REALTIME ns, from
    when the watch was due to wake to when it woke) the host kept a watch from running
    for :data:`RECORDED_NS` or more while the block ran, and ``w.worst_s``: the longest
    (seconds; 0.0 when none was recorded)."""

    def __init__(self, priority: int = WATCH_PRIORITY) -> None:
        self.priority = priority
        self.worst_s = 0.0
        self.stalls: list[tuple[int, int]] = []
        self._procs: list[subprocess.Popen[str]] = []

    def __enter__(self) -> StallWatch:
        try:
            for cpu in sorted(os.sched_getaffinity(0)):
                proc = subprocess.Popen(
                    [sys.executable, "-c", _SCRIPT, str(self.priority), str(cpu), str(RECORDED_NS)],
                    stdout=subprocess.PIPE,
                    text=True,
                )
                self._procs.append(proc)
                assert proc.stdout is not None
                assert proc.stdout.readline().strip() == "ready", f"no stall watch on cpu{cpu}"
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for proc in self._procs:
            proc.kill()
            out, _ = proc.communicate(timeout=10)
            for line in out.splitlines():
                start, end = (int(x) for x in line.split())
                self.stalls.append((start, end))
        self._procs = []
        self.stalls.sort()
        self.worst_s = max(((e - s) / 1e9 for s, e in self.stalls), default=0.0)

    def overlaps(self, start_ns: int, end_ns: int, least_s: float) -> bool:
        """A stall of ``least_s`` or more overlapped the interval (CLOCK_REALTIME ns)."""
        return any(e - s >= least_s * 1e9 and s < end_ns and e > start_ns for s, e in self.stalls)


def stalled(worst_s: float, threshold_s: float = 0.05) -> bool:
    """A stall long enough to explain a master's missed reply or an expired SM watchdog."""
    return worst_s >= threshold_s
