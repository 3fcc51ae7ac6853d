"""Run tools/kickcat_master.py in a master namespace; keep the CPUs busy meanwhile."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tests.integration.netns import NetnsPair

TOOL = Path(__file__).resolve().parents[2] / "tools" / "kickcat_master.py"


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
