"""The host probe (ecatsim/bench/steadiness.c) built and run on every CPU: one line each,
with every 10 ms window of its run counted. The speeds are the host's, not asserted.

Ref: docs/decisions.md B7.
"""

from __future__ import annotations

import os

from ecatsim.bench.steadiness import measure


def test_the_probe_measures_every_cpu_in_10_ms_windows() -> None:
    host = measure(300)  # one burst: 30 windows, the last cut short and dropped
    assert sorted(host["cpus"]) == sorted(os.sched_getaffinity(0))
    for figures in host["cpus"].values():
        assert figures["windows"] in (29, 30), figures
        assert 0.0 <= figures["min_speed"] <= figures["median_speed"] <= 1.5, figures
        assert 0.0 <= figures["stalled_pct"] <= figures["slowed_pct"] <= 100.0, figures
