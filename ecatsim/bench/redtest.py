"""``ecatsim bench --bringup N --master soem``: SOEM's own DC sample, red_test, as the
bring-up's master, for segments beyond pysoem's (199 slaves, a 4096-byte IO map).

red_test (built from pysoem's sdist with a larger slave table and IO map,
:func:`ecatsim.bench.soem.red_test`) does, as SOEM ships it: ec_config (config_init and
config_map; ec_config_overlap with ``--overlap``), SAFEOP, ec_configdc, OP requested with
its real-time cycle thread running (SCHED_FIFO 40, clock_nanosleep to absolute times,
receive then send, the cycle kept locked to the DC time of the replies with ec_sync), and
every 20 ms a line with the last WKC. It does not start SYNC0 (no ec_dcsync0; with
``--sync0`` the build adds SOEM's ec_dcsync0 for every slave after ec_configdc). The build
also runs the drives as the pysoem master does (:func:`ecatsim.bench.soem.drive_patches`:
csp by SDO, enabled from its main loop, holding their positions) and prints how many are
enabled in csp after its cycles. Its phases are marked in the capture
as its lines arrive (a phase's first frames may fall in the one before); the cycles, their
lost frames and WKCs are read off the wire by the capture on the master's end
(:func:`ecatsim.bench.capture.process_cycles`): SOEM's sum of the WKCs of each cycle's
frames against the WKC red_test prints as expected, a reply later than red_test waits
(:func:`timeout_ns`) lost.
Ref: docs/performance.md "How to measure".
"""

from __future__ import annotations

import re
import subprocess
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ecatsim.bench.capture import Capture
from ecatsim.bench.master import cpu_seconds
from ecatsim.bench.netns import NetnsPair
from ecatsim.bench.soem import RED_IOMAP, RED_MAXSLAVE, STOCK_TIMEOUT_US, pysoem_version

#: what the bench records of this master (``master_name`` and ``master_limits``)
NAME = "SOEM red_test"


def limits(sync0: bool) -> dict[str, object]:
    """The master's limits as built: slaves, IO map bytes, SOEM's version source, SYNC0
    started or not (``--sync0``), the drives enabled in csp."""
    return {"max_slaves": RED_MAXSLAVE - 1, "iomap_bytes": RED_IOMAP,
            "soem": f"pysoem {pysoem_version()} sdist", "sync0": sync0,
            "drives_enabled": True}  # fmt: skip


def timeout_ns(period_us: int, frame_timeout_us: int = STOCK_TIMEOUT_US) -> int:
    """How long after sending a frame red_test still takes its reply: its cycle thread
    receives a cycle's frames at the next cycle, waiting up to SOEM's EC_TIMEOUTRET
    (``frame_timeout_us``, 2 ms as shipped)."""
    return (period_us + frame_timeout_us) * 1000


def run_timeout(cycles: int, period_us: int) -> float:
    """How long red_test may run before it is killed: five minutes for the bring-up and
    three times its cycles' time (its cycle thread, SCHED_FIFO and always behind when the
    replies are late, can starve its main loop on the same CPU: ``--master-cpu``)."""
    return 300.0 + 3 * cycles * period_us / 1e6


#: red_test's lines and the phase each starts (its output, as SOEM ships it)
PHASES = (
    (re.compile(r"^(\d+) slaves found and configured"), "safeop_dc"),
    (re.compile(r"^Request operational state"), "op"),
    (re.compile(r"^Operational state reached for all slaves"), "cycles"),
    (re.compile(r"^Request safe operational state"), "end"),
)
EXPECTED = re.compile(r"^Calculated workcounter (\d+)")
#: the build's line after the cycles (:func:`ecatsim.bench.soem.drive_patches`)
ENABLED = re.compile(r"^Enabled drives (\d+) csp (\d+)")
#: red_test's check thread reports slaves out of OP, lost, recovered
TROUBLE = re.compile(r"^(ERROR|WARNING|MESSAGE|Slave \d+ State=)")


@dataclass
class RedTestRun:
    """What one red_test run printed: the slaves it configured, the WKC it expects, whether
    every slave reached OP, the drives enabled and in csp after the cycles (None: no such
    line), its check thread's reports, the daemon's CPU seconds over the cycles, and the
    output's last lines (for a failure)."""

    slaves: int = 0
    expected_wkc: int = 0
    all_op: bool = False
    drives_enabled: int | None = None
    drives_csp: int | None = None
    trouble: list[str] = field(default_factory=list)
    cycles_cpu_s: list[float] = field(default_factory=list)
    cycles_wall_ns: int = 0
    tail: list[str] = field(default_factory=list)
    returncode: int | None = None


def run(exe: Path, pair: NetnsPair, cap: Capture, period_us: int, daemon_pids: Sequence[int],
        prefix: tuple[str, ...] = (), timeout: float = 900.0) -> RedTestRun:  # fmt: skip
    """Run red_test on the master's interface (``prefix``: taskset/chrt before it), each
    phase marked in ``cap`` as its line arrives; killed after ``timeout`` seconds. The CPU
    seconds of each of ``daemon_pids`` over the cycles go to ``cycles_cpu_s``."""
    cmd = ["ip", "netns", "exec", pair.master_ns, *prefix, "stdbuf", "-oL", str(exe),
           pair.master_if, pair.master_if, str(period_us)]  # fmt: skip
    out = RedTestRun()
    cap.mark("config")
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
    watchdog = threading.Timer(timeout, proc.kill)
    watchdog.start()
    cpu0: list[float] = []
    t0 = 0
    try:
        assert proc.stdout is not None
        for line in proc.stdout:  # universal newlines: its "\r" progress lines too
            line = line.strip()
            if not line:
                continue
            out.tail = [*out.tail[-19:], line]
            for pattern, phase in PHASES:
                m = pattern.match(line)
                if m is None:
                    continue
                cap.mark(phase)
                if phase == "safeop_dc":
                    out.slaves = int(m.group(1))
                elif phase in ("op", "cycles"):  # the cycles: from OP (from the request without)
                    out.all_op = phase == "cycles"
                    cpu0, t0 = [cpu_seconds(p) for p in daemon_pids], cap.marks[-1][0]
                elif phase == "end":
                    out.cycles_cpu_s = [
                        cpu_seconds(p) - c for p, c in zip(daemon_pids, cpu0, strict=True)
                    ]
                    out.cycles_wall_ns = cap.marks[-1][0] - t0
            m = EXPECTED.match(line)
            if m is not None:
                out.expected_wkc = int(m.group(1))
            m = ENABLED.match(line)
            if m is not None:
                out.drives_enabled, out.drives_csp = int(m.group(1)), int(m.group(2))
            if TROUBLE.match(line) and len(out.trouble) < 50:
                out.trouble.append(line)
        out.returncode = proc.wait()
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return out
