"""``ecatsim bench --bringup N [--overlap]``: pysoem brings the daemon's drives to OP with
DC, enables each in csp and moves it; the capture on the master's end times every reply.
With SOEM's overlapped IO map the master must send with its overlapped send: the plain one
sends the last reply's inputs back as outputs, and no drive is ever enabled.

Ref: docs/performance.md "How to measure"; CiA 402-2 Figure 5 (the enable sequence).
"""

from __future__ import annotations

import os
import time
from typing import Any

import pytest

from ecatsim.bench import bringup
from tests.support.stall import REPEAT_PAUSE_S, spoiled

DRIVES = 4
#: runs at most, while the host spoils each (K7: its stalls and steal come in bursts)
RUNS = 3
PAUSE_S = REPEAT_PAUSE_S


#: the wide guard on what the bench's stock 2 ms master loses to the host (K9): at most one
#: cycle in this many lost or short of its WKC, and at most RESENDS bring-up frames resent;
#: the bench, not a pass/fail test, measures the reply times exactly
CYCLE_GUARD = 100
RESENDS = 2


def _clean(r: dict[str, Any]) -> bool:
    """Every request answered, and the frames a stock master lost within the guard."""
    cyc, frames = r["cycles"], r["frames"]
    return bool(
        cyc["lost"] + cyc["wkc_errors"] <= cyc["cycles"] // CYCLE_GUARD
        and frames["resends"] <= RESENDS
        and frames["unanswered"] == 0
    )


def _spoiled(r: dict[str, Any]) -> bool:
    """The run's steal time and its replies later than 2 ms or never, the first explained
    or not by the watch (ecatsim/bench/stallwatch.py), by the rule of :func:`spoiled`."""
    host = r.get("host_stalls", {})
    steal = r["cycles"].get("steal_s", 0.0) or 0.0
    late = host.get("late_replies", 0) + r["frames"]["unanswered"]
    return spoiled(steal, late, host.get("late_when_slowed", 0))


def run_bringup(*args: Any, **kwargs: Any) -> dict[str, Any]:
    """:func:`ecatsim.bench.bringup.run_bringup`, run again (at most :data:`RUNS` runs,
    :data:`PAUSE_S` apart) only while a run that lost a frame past the guard was spoiled
    by the host; the last run is returned, so the test's assertions still need a clean
    one."""
    for _ in range(RUNS - 1):
        r = bringup.run_bringup(*args, **kwargs)
        if _clean(r) or not _spoiled(r):
            return r
        time.sleep(PAUSE_S)
    return bringup.run_bringup(*args, **kwargs)


@pytest.mark.parametrize("overlap", [False, True], ids=["map", "overlap"])
def test_the_bringup_bench_enables_every_drive_and_loses_nothing(overlap: bool) -> None:
    r = run_bringup(DRIVES, 300, 1000, overlap, ())
    assert r["slaves"] == DRIVES and r["overlap"] is overlap
    cyc = r["cycles"]
    assert cyc["cycles"] == 300
    assert cyc["expected_wkc"] == 3 * DRIVES  # per drive: 1 for the read, 2 for the write
    assert cyc["drives_enabled"] == DRIVES
    assert _clean(r), (cyc, r["frames"])


def test_the_bringup_bench_chains_daemons_into_one_segment() -> None:
    """``--chain 2``: the drives in two daemons, the second behind the first's
    --out-iface, each pinned to its own CPU; the master sees one segment of all of them."""
    r = run_bringup(5, 300, 1000, False, (), chain=2)
    assert [d["slaves"] for d in r["chain"]] == [3, 2]
    cpus = sorted(os.sched_getaffinity(0))
    assert [d["flags"] for d in r["chain"]] == [
        ["--cpu", str(cpus[k % len(cpus)])] for k in range(2)
    ]
    cyc = r["cycles"]
    assert cyc["expected_wkc"] == 3 * 5
    assert cyc["drives_enabled"] == 5
    assert len(cyc["daemon_cpu_percent"]) == 2 and all(x > 0 for x in cyc["daemon_cpu_percent"])
    assert _clean(r), (cyc, r["frames"])


def test_the_bringup_bench_restarts_a_master_against_the_running_segment() -> None:
    """``--restart``: a first master brings the drives to OP, runs 200 cycles and closes;
    a second one's bring-up, over slaves still configured and in OP, is the one timed (its
    config_init clears their FMMUs and SMs by broadcast) and ends with every drive enabled
    again."""
    r = run_bringup(DRIVES, 300, 1000, False, (), restart=True)
    assert r["restart"] is True
    assert r["frames"]["phases"]["config_init"]["frames"] > 0
    cyc = r["cycles"]
    assert cyc["cycles"] == 300 and cyc["drives_enabled"] == DRIVES
    assert _clean(r), (cyc, r["frames"])
