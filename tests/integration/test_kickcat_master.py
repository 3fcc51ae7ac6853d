"""KickCAT (pinned, default settings: 2 ms link timeout) brings the default segment to OP,
beside pysoem, on an idle machine and with both CPUs kept busy by other processes.

KickCAT polls for its reply right after sending and naps between polls; on a busy host a
nap can end after its deadline, and it does not look once more. The daemon therefore runs
on the CPU the master's frames come from (decision K5), so the reply is queued before
KickCAT's first poll. The daemon's own part is checked on every run as well: every request
a kernel timestamp sees arrive at the daemon's interface gets its reply at the master's
interface (ecatsim/bench/capture.py), on an idle machine every one well inside the 2 ms.
The figure over 20 runs is in bench/results (tools/kickcat_load.py).

The single run pins KickCAT to one CPU, as real-time masters run (decision K6): a master the
scheduler moves to another CPU sends its next frame from a CPU the daemon has not followed
to yet, naps for the reply, and a nap that another process ends late loses a reply that
came in time ("Bus.cc:802: Error while fetching eeprom data" with the reply 244 us after
the request). The runs under load leave KickCAT where the scheduler puts it.
Ref: ETG.1000.6 §6.4 (AL state machine) as a second, independent master implements it."""

from __future__ import annotations

import os
from typing import Any

import pytest

from tests.integration.netns import NetnsPair
from tests.support.kickcat import busy_cpus, kickcat_until_clean, one_trial

pytestmark = pytest.mark.integration

#: the daemon's reply time, 99th percentile, under load (measured: 60-300 us)
LOADED_P99_US = 1000


def timed_trial(pair: NetnsPair) -> tuple[dict[str, Any], dict[str, Any]]:
    trial = one_trial(pair)
    return trial.result, trial.replies


def test_kickcat_reaches_op_and_runs_500_cycles(netns_pair: NetnsPair, daemon_factory: Any) -> None:
    """KickCAT, with its stock 2 ms timeout, reaches OP and runs every cycle; every request
    gets its reply, at most one in 200 later than 2 ms (a wide guard: K7). A run that fails
    either is run again from power-up only when the host stalled or slowed a CPU
    (ecatsim/bench/stallwatch.py) during each late reply and within 2 ms of the request
    KickCAT gave up on; otherwise it fails the test (tests/support/kickcat.py)."""
    d = daemon_factory()
    expected = {"ok": True, "stage": "done", "slaves": 1, "cycles": 500}
    cpu = max(os.sched_getaffinity(0))
    trial = kickcat_until_clean(netns_pair, d.restart, expected, master_cpu=cpu)
    assert trial.replies["frames"] > 1000, trial.replies


def test_kickcat_under_load_with_the_daemons_default_flags(
    netns_pair: NetnsPair, daemon_factory: Any
) -> None:
    """Both CPUs busy with processes at nice 0, KickCAT at nice 0 with its defaults, 5 runs
    from power-up: KickCAT reaches OP and runs 500 cycles in at least 4 of the 5, and the
    daemon answers every frame, 99 % of them within LOADED_P99_US. (A single reply can
    still take milliseconds on a loaded host, with or without decision K5: 2.4 ms in about
    one of 8000 frames here, so the bound is on the 99th percentile.)"""
    d = daemon_factory()
    runs = []
    with busy_cpus(os.cpu_count() or 2):
        for _ in range(5):
            runs.append(timed_trial(netns_pair))
            d.restart()
    for result, replies in runs:
        assert replies["unpaired"] == 0, (result, replies)
        assert replies["p99"] < LOADED_P99_US, (result, replies)
    assert sum(r["ok"] for r, _ in runs) >= 4, runs
