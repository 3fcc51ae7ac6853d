"""The host's stalls and slow spots while a run goes on: on every CPU the program
``stallwatch.c``, pinned, above every real-time thread of the run (SCHED_FIFO 60: above
the daemon's 20-40 and a master's 30-40), wakes every millisecond and runs a computation
of about 10 us. It records each wake :data:`RECORDED_NS` or more late (a stall: the host
did not run the CPU) and each computation below 30 % of its unhindered speed (a slow
spot: the host ran it slowly, decision B7). A virtual CPU the host stops or slows takes
every thread on it along, master and daemon alike, so a reply late past a master's
timeout during a stall or a slow spot is the host's, not the daemon's (decision B8). The
watch costs each CPU about 1 %.

    with StallWatch() as w:
        ...  # the run
    w.stalls, w.slow          # [(from, to)] CLOCK_REALTIME ns, the capture's clock
    w.overlaps(a, b, 0.001)
    w.steal_s                 # the hypervisor's steal time meanwhile, all CPUs (s)
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path
from types import TracebackType

from ecatsim.bench.floor import build_c
from ecatsim.bench.master import steal_seconds

SOURCE = "stallwatch.c"
#: the watch's priority: above the daemon's (20, or --rt-priority up to 40) and a master's
WATCH_PRIORITY = 60
#: a wake this late (ns) is recorded as a stall
RECORDED_NS = 500_000


class StallWatch:
    """``with StallWatch() as w: ...`` then ``w.stalls``: when (CLOCK_REALTIME ns, from
    when a watch was due to wake to when it woke) the host kept a watch from running for
    :data:`RECORDED_NS` or more while the block ran, ``w.slow``: when it ran a watch's
    computation below 30 % of its speed, ``w.worst_s``: the longest stall (seconds;
    0.0 when none was recorded), and ``w.steal_s``: the steal time of all CPUs while the
    block ran (seconds; the kernel counts it in ticks, too coarse to place against one
    reply). Needs a C compiler, and CAP_SYS_NICE for SCHED_FIFO."""

    def __init__(self, priority: int = WATCH_PRIORITY) -> None:
        self.priority = priority
        self.worst_s = 0.0
        self.steal_s = 0.0
        self._steal0: list[float] = []
        self.stalls: list[tuple[int, int]] = []
        self.slow: list[tuple[int, int]] = []
        self._procs: list[subprocess.Popen[str]] = []
        self._tmp: tempfile.TemporaryDirectory[str] | None = None

    def __enter__(self) -> StallWatch:
        self._tmp = tempfile.TemporaryDirectory(prefix="ecatsim-stallwatch-")
        self._steal0 = steal_seconds()
        try:
            exe = build_c(SOURCE, Path(self._tmp.name) / "stallwatch")
            for cpu in sorted(os.sched_getaffinity(0)):
                args = (str(cpu), str(self.priority), str(RECORDED_NS))
                proc = subprocess.Popen([str(exe), *args], stdout=subprocess.PIPE, text=True)
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
                kind, start, end, *_ = line.split()
                (self.stalls if kind == "stall" else self.slow).append((int(start), int(end)))
        self._procs = []
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
        self.stalls.sort()
        self.slow.sort()
        self.worst_s = max(((e - s) / 1e9 for s, e in self.stalls), default=0.0)
        if self._steal0:
            self.steal_s = round(sum(steal_seconds()) - sum(self._steal0), 2)
            self._steal0 = []

    def overlaps(self, start_ns: int, end_ns: int, least_s: float) -> bool:
        """A stall of ``least_s`` or more overlapped the interval (CLOCK_REALTIME ns)."""
        return any(e - s >= least_s * 1e9 and s < end_ns and e > start_ns for s, e in self.stalls)

    def slowed(self, start_ns: int, end_ns: int) -> bool:
        """A slow spot overlapped the interval (CLOCK_REALTIME ns)."""
        return any(s < end_ns and e > start_ns for s, e in self.slow)

    def explains(self, start_ns: int, end_ns: int, least_s: float) -> bool:
        """The host stalled (``least_s`` or more) or slowed a CPU during the interval."""
        return self.overlaps(start_ns, end_ns, least_s) or self.slowed(start_ns, end_ns)

    def report(
        self,
        late: list[tuple[int, int]],
        least_s: float = 0.001,
        over_1ms: list[tuple[int, int]] | None = None,
    ) -> dict[str, float]:
        """For the JSON: how many stalls of ``least_s`` or more, the longest stall (ms),
        the slow spots, and how many of the ``late`` replies (request to reply,
        CLOCK_REALTIME ns) a stall or a slow spot overlapped. With ``over_1ms`` (the
        replies 1 ms or more late), the same for them against every recorded stall
        (:data:`RECORDED_NS` or more): what the 99.9 %-within-1-ms count owes the host."""
        long = sum(e - s >= least_s * 1e9 for s, e in self.stalls)
        r = {"least_ms": least_s * 1e3, "stalls": long,
             "longest_ms": round(self.worst_s * 1e3, 2), "slow_spots": len(self.slow),
             "late_replies": len(late),
             "late_in_a_stall": sum(self.overlaps(a, b, least_s) for a, b in late),
             "late_when_slowed": sum(self.explains(a, b, least_s) for a, b in late)}  # fmt: skip
        if over_1ms is not None:
            least = RECORDED_NS / 1e9
            r.update(over_1ms=len(over_1ms),
                     over_1ms_in_a_stall=sum(self.overlaps(a, b, least) for a, b in over_1ms),
                     over_1ms_when_slowed=sum(self.explains(a, b, least)
                                              for a, b in over_1ms))  # fmt: skip
        return r

    @staticmethod
    def text(r: dict[str, float]) -> str:
        """One line of :meth:`report`."""
        return (f"host during the run: {r['stalls']} stalls of {r['least_ms']:g} ms or more "
                f"(longest {r['longest_ms']} ms), {r['slow_spots']} slow spots; replies over "
                f"2 ms: {r['late_replies']}, {r['late_in_a_stall']} during a stall, "
                f"{r['late_when_slowed']} during a stall or a slow spot"
                + (f"; over 1 ms: {r['over_1ms']}, {r['over_1ms_in_a_stall']} during a "
                   f"stall of {RECORDED_NS / 1e6:g} ms or more, "
                   f"{r['over_1ms_when_slowed']} during one or a slow spot"
                   if "over_1ms" in r else ""))  # fmt: skip
