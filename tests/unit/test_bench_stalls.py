"""The bench's record of the host's stalls and of each daemon's ``stopped`` line
(ecatsim/bench/stallwatch.py, ecatsim/bench/bringup.py, capture.late_replies).

Ref: docs/decisions.md B8.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ecatsim.bench.bringup import stopped_line
from ecatsim.bench.capture import Frame, late_replies
from ecatsim.bench.stallwatch import StallWatch

MS = 1_000_000


def frame(t_ms: float, reply: bool, idx: int) -> Frame:
    return Frame(round(t_ms * MS), reply, idx, 12, 0, 0, 4, b"\x00" * 4)


def test_late_replies_are_the_requests_answered_that_late_or_later() -> None:
    frames = [
        frame(0.0, False, 1), frame(0.5, True, 1),  # 0.5 ms
        frame(1.0, False, 2), frame(3.0, True, 2),  # 2.0 ms: as late as the bound
        frame(4.0, False, 3), frame(6.5, True, 3),  # 2.5 ms
        frame(7.0, False, 4),  # never answered: not a late reply
    ]  # fmt: skip
    assert late_replies(frames, 2000) == [(1 * MS, 3 * MS), (4 * MS, 6_500_000)]


def test_the_report_counts_late_replies_that_a_long_enough_stall_overlapped() -> None:
    w = StallWatch()
    w.stalls = [(10 * MS, 11_500_000), (20 * MS, 20_600_000), (30 * MS, 33 * MS)]
    w.worst_s = 0.003
    late = [(9 * MS, 12 * MS), (19 * MS, 22 * MS), (31 * MS, 34 * MS), (40 * MS, 43 * MS)]
    r = w.report(late)
    # the second overlaps only a 0.6 ms stall, the fourth none
    assert r == {"least_ms": 1.0, "stalls": 2, "longest_ms": 3.0, "late_replies": 4,
                 "late_in_a_stall": 2}  # fmt: skip
    assert StallWatch.text(r) == (
        "host stalls during the run: 2 of 1 ms or more (longest 3.0 ms); replies over 2 ms: "
        "4, 2 of them during such a stall"
    )


def test_the_watch_runs_on_every_cpu_and_records_stalls_in_the_capture_s_clock() -> None:
    """(SCHED_FIFO: needs root, as the bench does.)"""
    before = time.time_ns()
    with StallWatch() as w:
        assert len(w._procs) == len(os.sched_getaffinity(0))
        time.sleep(0.3)
    after = time.time_ns()
    assert not w._procs
    assert all(before <= s < e <= after for s, e in w.stalls), w.stalls
    assert w.worst_s == max(((e - s) / 1e9 for s, e in w.stalls), default=0.0)


def test_the_daemon_s_stopped_line_is_read_from_its_log(tmp_path: Path) -> None:
    log = tmp_path / "daemon.log"
    stopped = {"event": "stopped", "frames": 10, "sync0_merged": 3, "gc_max_us": 120,
               "failures": 0, "level": "info", "timestamp": "x"}  # fmt: skip
    log.write_text('{"event": "ready"}\nnot json\n' + json.dumps(stopped) + "\n")
    assert stopped_line(log) == {"frames": 10, "sync0_merged": 3, "gc_max_us": 120, "failures": 0}
    log.write_text('{"event": "ready"}\n')  # killed: no stopped line
    assert stopped_line(log) == {}
