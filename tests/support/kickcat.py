"""Run tools/kickcat_master.py in a master namespace; keep the CPUs busy meanwhile; repeat a
run the host spoiled (a stall measured by tests/support/stall.py), and only such a run."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from ecatsim.bench.capture import Capture, late_replies, reply_stats
from tests.integration.netns import NetnsPair
from tests.support.stall import REPEAT_PAUSE_S, StallWatch, spoiled

TOOL = Path(__file__).resolve().parents[2] / "tools" / "kickcat_master.py"

#: KickCAT's default link timeout: a reply later than this is a lost frame to it
KICKCAT_TIMEOUT_US = 2000
#: KickCAT runs at most, while the host spoils each: a CI machine's stalls and steal time
#: come in bursts of seconds, so a repeat waits :data:`PAUSE_S` after the run before it
RUNS = 8
PAUSE_S = REPEAT_PAUSE_S
#: the wide guard on the capture's reply times in a run KickCAT completed: at most one reply
#: in this many later than KickCAT's timeout (decision K7; the bench measures them exactly)
LATE_GUARD = 200
#: a host stall that can cost KickCAT a frame: half its link timeout, with the daemon's own
#: reply time (tens of microseconds for one slave) and KickCAT's polling naps on top
HOST_STALL_S = 0.001


def kickcat_trial(
    pair: NetnsPair,
    cycles: int = 500,
    master_rt: int | None = None,
    master_cpu: int | None = None,
) -> dict[str, Any]:
    """One KickCAT run (INIT scan to OP, then ``cycles`` cycles): its JSON result.
    ``master_rt``: run the master SCHED_FIFO at this priority, as real-time masters run.
    ``master_cpu``: pin the master to this CPU (``taskset``), as real-time masters run."""
    rt = ["chrt", "-f", str(master_rt)] if master_rt else []
    pin = ["taskset", "-c", str(master_cpu)] if master_cpu is not None else []
    cmd = ["ip", "netns", "exec", pair.master_ns, *pin, *rt, sys.executable, str(TOOL)]
    cmd += ["--iface", pair.master_if, "--cycles", str(cycles)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        return {"ok": False, "stage": "start", "error": (r.stderr or r.stdout)[-300:]}
    result: dict[str, Any] = json.loads(lines[-1])
    return result


@contextmanager
def busy_cpus(n: int) -> Iterator[None]:
    """``n`` processes at nice 0 spinning, as other jobs on a CI machine do."""
    spin = [sys.executable, "-c", "while True: pass"]
    procs = [subprocess.Popen(spin) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


@dataclass
class Trial:
    """One KickCAT run: its JSON result, the reply times a capture at both ends saw
    (:func:`ecatsim.bench.capture.reply_stats`), where it needs the host to explain it (the
    requests answered later than KickCAT's timeout, and for a run KickCAT gave up, its last
    request and the timeout after it: CLOCK_REALTIME ns) and the host stalls a watch on
    every CPU saw meanwhile (tests/support/stall.py), and the time the hypervisor took from
    this VM's CPUs during the run (steal time, summed over the CPUs: the kernel's count, in
    its 10 ms ticks)."""

    result: dict[str, Any]
    replies: dict[str, Any]
    late: list[tuple[int, int]]
    watch: StallWatch
    steal_s: float = 0.0

    def clean(self, expected: dict[str, Any]) -> bool:
        """The run completed as expected (KickCAT, with its stock 2 ms timeout, judged every
        frame it waited for), every request had its reply, and at most one in
        :data:`LATE_GUARD` came later than that timeout: a wide guard, as timing belongs to
        the bench (decision K7)."""
        guard = self.replies["frames"] // LATE_GUARD
        return self.result == expected and self.replies["unpaired"] == 0 and len(self.late) <= guard

    def spoiled_by_the_host(self) -> bool:
        """The host stalled a CPU for :data:`HOST_STALL_S` or more, or ran it below 30 % of
        its speed, during each reply later than KickCAT's timeout and, if KickCAT gave up,
        within its timeout of the last request (ecatsim/bench/stallwatch.py); or the
        hypervisor reported taking CPU time from this VM during the run (steal time: too
        coarse to place against a reply, so the run is spoiled as a whole). Either way a
        run is only repeated: the test still needs a clean one (:func:`spoiled`)."""
        explained = sum(self.watch.explains(*t, HOST_STALL_S) for t in self.late)
        return spoiled(self.steal_s, len(self.late), explained)

    def __str__(self) -> str:
        return (f"{self.result} replies {self.replies}, {len(self.late)} late or last, longest "
                f"host stall {self.watch.worst_s * 1e3:.2f} ms, "
                f"steal {self.steal_s:.2f} s")  # fmt: skip


def one_trial(pair: NetnsPair, expected: dict[str, Any] | None = None, **kwargs: Any) -> Trial:
    """A :func:`kickcat_trial` under a stall watch, captured at both ends; a result other
    than ``expected`` makes its last request one to explain."""
    with StallWatch() as watch:
        ends = (pair.master_ns, pair.master_if), (pair.slave_ns, pair.slave_if)
        with Capture.both_ends(*ends) as rt:
            result = kickcat_trial(pair, **kwargs)
    frames = rt.frames()
    timeout_ns = KICKCAT_TIMEOUT_US * 1000
    late = late_replies(frames, KICKCAT_TIMEOUT_US)
    requests = [f.t_ns for f in frames if not f.reply]
    if expected is not None and result != expected and requests:
        late.append((requests[-1], requests[-1] + timeout_ns))
    return Trial(result, reply_stats(frames), late, watch, watch.steal_s)


def kickcat_until_clean(
    pair: NetnsPair,
    restart: Callable[[], None],
    expected: dict[str, Any],
    runs: int = RUNS,
    **kwargs: Any,
) -> Trial:
    """Run KickCAT (``kickcat_trial(pair, **kwargs)``) until a run is :meth:`Trial.clean`.

    A run that is not clean fails the test at once unless the host spoiled it
    (:meth:`Trial.spoiled_by_the_host`: KickCAT gives up on the first frame late past 2 ms,
    and a descheduled virtual CPU stops the daemon and the master alike): only then it is
    run again from power-up (``restart()``), :data:`PAUSE_S` after it, at most ``runs`` runs
    in all."""
    spoiled: list[str] = []
    for _ in range(runs):
        trial = one_trial(pair, expected, **kwargs)
        if trial.clean(expected):
            return trial
        if not trial.spoiled_by_the_host():
            pytest.fail(f"KickCAT's run failed, not for a host stall: {trial}; before: {spoiled}")
        spoiled.append(str(trial))
        time.sleep(PAUSE_S)
        restart()
    pytest.fail(f"the host stalled in each of {runs} KickCAT runs: {spoiled}")
