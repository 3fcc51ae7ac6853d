"""The host probe (ecatsim/bench/steadiness.c) built and run on every CPU: one line each,
with every 10 ms window of its run counted. The speeds are the host's, not asserted.

Ref: docs/decisions.md B7.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

from ecatsim.bench.floor import build_c
from ecatsim.bench.steadiness import SOURCE, measure, parse


def test_the_probe_measures_every_cpu_in_10_ms_windows() -> None:
    host = measure(300)  # one burst: 30 windows, the last cut short and dropped
    assert sorted(host["cpus"]) == sorted(os.sched_getaffinity(0))
    for figures in host["cpus"].values():
        assert figures["windows"] in (29, 30), figures
        assert 0.0 <= figures["min_speed"] <= figures["median_speed"] <= 1.5, figures
        assert 0.0 <= figures["stalled_pct"] <= figures["slowed_pct"] <= 100.0, figures


def test_a_stall_leaves_the_windows_it_covers_at_zero(tmp_path: Path) -> None:
    """The windows are a fixed 10 ms grid: the probe stopped for 60 ms (SIGSTOP, as a host
    that deschedules the CPU) leaves at least five windows with no repetition, still 29-30
    windows in 300 ms, rather than one window stretched over the stall."""
    exe = build_c(SOURCE, tmp_path / "steadiness")
    cpu = min(os.sched_getaffinity(0))
    p = subprocess.Popen([str(exe), str(cpu), "300"], stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(0.1)
        p.send_signal(signal.SIGSTOP)
        time.sleep(0.06)
        p.send_signal(signal.SIGCONT)
        out, _ = p.communicate(timeout=10)
    finally:
        p.kill()
    counts = [int(w) for w in out.split()[7:]]
    assert len(counts) in (29, 30), counts
    assert sum(c == 0 for c in counts) >= 5, counts
    _, figures = parse(out.strip())
    assert figures["stalled_pct"] >= 5 * 100 / len(counts) - 0.1, figures
