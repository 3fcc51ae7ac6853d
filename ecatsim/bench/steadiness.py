"""How steadily the host's CPUs run: the probe ``steadiness.c``, on every CPU at once.

A reply time is only as steady as the CPU that computes it. On a virtual machine the
hypervisor may give a CPU less than its full speed for tens of milliseconds (another guest
on the same core) without reporting it as steal time, and a daemon that needs half a CPU
then falls behind, whatever its own code does. The probe, pinned to each CPU at
SCHED_FIFO priority 30 (above the daemon's 20, so nothing on this host takes the CPU from
it), counts how many repetitions of a fixed computation finish in every 10 ms window; a
window's *speed* is that count against the CPU's unhindered rate (the 10th percentile of
the repetitions' durations). On steady hardware every window is near 1.

``ecatsim bench --bringup`` measures the host this way before each run and keeps the
figures with the run's results, so a table can say what the host did (decision B7).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ecatsim.bench.floor import build_c

SOURCE = "steadiness.c"
#: speeds below which a 10 ms window counts as slowed / as nearly stopped
SLOWED = 0.6
STALLED = 0.3


def analyse(chunk_ns: int, window_ns: int, counts: Sequence[int]) -> dict[str, Any]:
    """One CPU's windows: how many, the share slowed below ``SLOWED`` and ``STALLED`` of
    the unhindered speed (per cent), the slowest window's speed and the median's."""
    if chunk_ns <= 0 or not counts:
        return {"windows": 0}
    speeds = sorted(c * chunk_ns / window_ns for c in counts)
    n = len(speeds)
    return {
        "windows": n,
        "slowed_pct": round(100 * sum(s < SLOWED for s in speeds) / n, 1),
        "stalled_pct": round(100 * sum(s < STALLED for s in speeds) / n, 1),
        "min_speed": round(speeds[0], 2),
        "median_speed": round(speeds[n // 2], 2),
    }


def parse(line: str) -> tuple[int, dict[str, Any]]:
    """The probe's line ``cpu N chunk_ns P window_ns W counts C...`` as (N, analysis)."""
    words = line.split()
    if len(words) < 7 or words[0] != "cpu" or words[6] != "counts":
        raise ValueError(f"steadiness probe: unexpected output {line[:80]!r}")
    cpu, chunk_ns, window_ns = int(words[1]), int(words[3]), int(words[5])
    return cpu, analyse(chunk_ns, window_ns, [int(w) for w in words[7:]])


def measure(milliseconds: int = 2000) -> dict[str, Any]:
    """The probe on every CPU this process may use, all at once, for ``milliseconds``
    (in 400 ms bursts); {"cpus": {N: analysis}}."""
    with tempfile.TemporaryDirectory(prefix="ecatsim-steadiness-") as tmp:
        exe = build_c(SOURCE, Path(tmp) / "steadiness")
        procs = [
            subprocess.Popen(
                [str(exe), str(cpu), str(milliseconds)],
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
            for cpu in sorted(os.sched_getaffinity(0))
        ]
        out: dict[int, dict[str, Any]] = {}
        for p in procs:
            text, _ = p.communicate(timeout=milliseconds / 1000 * 2 + 30)
            cpu, figures = parse(text.strip())
            out[cpu] = figures
    return {"milliseconds": milliseconds, "cpus": out}


def text(host: dict[str, Any]) -> str:
    """One line: per CPU the share of 10 ms windows slowed and stalled, the slowest."""
    parts = [
        f"cpu{cpu} {f['slowed_pct']} % below {SLOWED:.0%} speed, {f['stalled_pct']} % below "
        f"{STALLED:.0%}, slowest {f['min_speed']}"
        for cpu, f in sorted(host["cpus"].items())
        if f.get("windows")
    ]
    return "host steadiness (10 ms windows): " + "; ".join(parts)
