"""Host stalls while a run goes on: on every CPU a process above every real-time thread of
the run (SCHED_FIFO 60: above the daemon's 20-40 and a master's 30-40) sleeps 1 ms at a
time and records each wake that came :data:`RECORDED_NS` or more late. A virtual CPU the
host deschedules stops every thread on it, master and daemon alike, so a reply late past
a master's timeout during such a stall is the host's, not the daemon's (decision B8).
The watch costs each CPU one short wake-up a millisecond.

    with StallWatch() as w:
        ...  # the run
    w.stalls        # [(from, to)] CLOCK_REALTIME ns, the capture's clock
    w.overlaps(a, b, 0.001)
"""

from __future__ import annotations

import os
import subprocess
import sys
from types import TracebackType

#: the watch's priority: above the daemon's (20, or --rt-priority up to 40) and a master's
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
    when a watch was due to wake to when it woke) the host kept a watch from running for
    :data:`RECORDED_NS` or more while the block ran, and ``w.worst_s``: the longest
    (seconds; 0.0 when none was recorded). Needs CAP_SYS_NICE for SCHED_FIFO."""

    def __init__(self, priority: int = WATCH_PRIORITY) -> None:
        self.priority = priority
        self.worst_s = 0.0
        self.stalls: list[tuple[int, int]] = []
        self._procs: list[subprocess.Popen[str]] = []

    def __enter__(self) -> StallWatch:
        try:
            for cpu in sorted(os.sched_getaffinity(0)):
                args = (str(self.priority), str(cpu), str(RECORDED_NS))
                proc = subprocess.Popen(
                    [sys.executable, "-c", _SCRIPT, *args], stdout=subprocess.PIPE, text=True
                )
                self._procs.append(proc)
                assert proc.stdout is not None
                if proc.stdout.readline().strip() != "ready":
                    raise RuntimeError(f"the stall watch did not start on cpu{cpu}")
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

    def report(self, late: list[tuple[int, int]], least_s: float = 0.001) -> dict[str, float]:
        """For the JSON: how many stalls of ``least_s`` or more, the longest stall (ms),
        and how many of the ``late`` replies (request to reply, CLOCK_REALTIME ns) one of
        them overlapped."""
        long = sum(e - s >= least_s * 1e9 for s, e in self.stalls)
        return {"least_ms": least_s * 1e3, "stalls": long,
                "longest_ms": round(self.worst_s * 1e3, 2), "late_replies": len(late),
                "late_in_a_stall": sum(self.overlaps(a, b, least_s) for a, b in late)}  # fmt: skip

    @staticmethod
    def text(r: dict[str, float]) -> str:
        """One line of :meth:`report`."""
        return (f"host stalls during the run: {r['stalls']} of {r['least_ms']:g} ms or more "
                f"(longest {r['longest_ms']} ms); replies over 2 ms: {r['late_replies']}, "
                f"{r['late_in_a_stall']} of them during such a stall")  # fmt: skip
