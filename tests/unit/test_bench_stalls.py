"""The bench's record of the host's stalls and of each daemon's ``stopped`` line
(ecatsim/bench/stallwatch.py, ecatsim/bench/bringup.py, capture.late_replies).

Ref: docs/decisions.md B8.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from ecatsim.bench.bringup import stopped_counts
from ecatsim.bench.capture import Frame, late_replies
from ecatsim.bench.netns import Daemon, Port
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


def test_the_report_counts_late_replies_that_a_stall_or_a_slow_spot_overlapped() -> None:
    w = StallWatch()
    w.stalls = [(10 * MS, 11_500_000), (20 * MS, 20_600_000), (30 * MS, 33 * MS)]
    w.slow = [(41 * MS, 41_100_000)]
    w.worst_s = 0.003
    late = [(9 * MS, 12 * MS), (19 * MS, 22 * MS), (31 * MS, 34 * MS), (40 * MS, 43 * MS),
            (50 * MS, 53 * MS)]  # fmt: skip
    r = w.report(late)
    # the first and third overlap a stall of 1 ms or more, the second only a 0.6 ms one, the
    # fourth a slow spot, the fifth nothing
    assert r == {"least_ms": 1.0, "stalls": 2, "longest_ms": 3.0, "slow_spots": 1,
                 "late_replies": 5, "late_in_a_stall": 2, "late_when_slowed": 3}  # fmt: skip
    assert StallWatch.text(r) == (
        "host during the run: 2 stalls of 1 ms or more (longest 3.0 ms), 1 slow spots; "
        "replies over 2 ms: 5, 2 during a stall, 3 during a stall or a slow spot"
    )


def test_replies_over_1_ms_are_set_against_every_recorded_stall() -> None:
    w = StallWatch()
    w.stalls = [(10 * MS, 10_600_000), (20 * MS, 20_400_000)]
    w.slow = [(31 * MS, 31_100_000)]
    w.worst_s = 0.0006
    over = [(9_500_000, 11 * MS), (19_500_000, 21 * MS), (30_500_000, 32 * MS),
            (40 * MS, 41_200_000)]  # fmt: skip
    r = w.report([], over_1ms=over)
    # the first overlaps a 0.6 ms stall (recorded: 0.5 ms or more); the second a 0.4 ms
    # one, which the watch never records, here planted to show it does not count; the
    # third a slow spot; the fourth nothing
    assert (r["over_1ms"], r["over_1ms_in_a_stall"], r["over_1ms_when_slowed"]) == (4, 1, 2)
    assert (r["stalls"], r["late_replies"]) == (0, 0)
    assert StallWatch.text(r).endswith(
        "; over 1 ms: 4, 1 during a stall of 0.5 ms or more, 2 during one or a slow spot"
    )
    assert "over 1 ms" not in StallWatch.text(w.report([]))


def test_the_watch_runs_on_every_cpu_and_records_stalls_in_the_capture_s_clock() -> None:
    """(SCHED_FIFO: needs root, as the bench does.)"""
    before = time.time_ns()
    with StallWatch() as w:
        assert len(w._procs) == len(os.sched_getaffinity(0))
        time.sleep(0.3)
    after = time.time_ns()
    assert not w._procs
    assert all(before <= s < e <= after for s, e in w.stalls + w.slow), (w.stalls, w.slow)
    assert w.worst_s == max(((e - s) / 1e9 for s, e in w.stalls), default=0.0)


def test_the_daemon_s_stopped_line_is_read_from_its_log(tmp_path: Path) -> None:
    log = tmp_path / "daemon.log"
    d = Daemon(Port("ns", "veth0"), (), log)
    d.starts = 2  # the lines of the current start count, after its marker
    stopped = {"event": "stopped", "frames": 10, "sync0_merged": 3, "gc_max_us": 120,
               "failures": 0, "level": "info", "timestamp": "x"}  # fmt: skip
    earlier = json.dumps(stopped | {"frames": 99})
    log.write_text(f"--- start 1: x\n{earlier}\n--- start 2: x\n" + '{"event": "ready"}\n'
                   "not json\n" + json.dumps(stopped) + "\n")  # fmt: skip
    assert stopped_counts(d) == {"frames": 10, "sync0_merged": 3, "gc_max_us": 120, "failures": 0}
    log.write_text(f"--- start 1: x\n{earlier}\n--- start 2: x\n" + '{"event": "ready"}\n')
    assert stopped_counts(d) == {}  # killed: no stopped line in this start


def test_a_master_that_gives_up_is_one_line_with_the_host_s_part() -> None:
    """The bring-up's master failing (a pysoem error, or the bench's own SystemExit) ends the
    run with its error and the host's stalls against the late replies seen until then."""
    from ecatsim.bench.bringup import gave_up, master_errors

    w = StallWatch()
    w.stalls = [(10 * MS, 13 * MS)]
    w.worst_s = 0.003
    frames = [frame(9.5, False, 1), frame(13.5, True, 1), frame(20.0, False, 2),
              frame(20.1, True, 2)]  # fmt: skip
    line = gave_up("ConfigMapError [PacketError(48, 1)]", frames, w)
    assert line == (
        "bench: the master gave up during its bring-up: ConfigMapError [PacketError(48, 1)]; "
        "host during the run: 1 stalls of 1 ms or more (longest 3.0 ms), 0 slow spots; "
        "replies over 2 ms: 1, 1 during a stall, 1 during a stall or a slow spot"
    )
    assert "\n" not in line
    names = ("ConfigMapError", "SdoError", "PacketError", "MailboxError", "WkcError",
             "EepromError")  # fmt: skip
    fake = SimpleNamespace(**{k: type(k, (Exception,), {}) for k in names})  # pysoem's names
    assert master_errors(fake) == (SystemExit, *(getattr(fake, k) for k in names))


def test_a_kickcat_run_is_spoiled_by_a_stall_over_each_late_reply_or_by_steal_time() -> None:
    """A late reply is the host's when a stall overlapped it, or when the hypervisor took
    CPU time during the run (steal time); a run with no late reply is never spoiled."""
    from tests.support.kickcat import Trial

    w = StallWatch()
    w.stalls = [(10 * MS, 12 * MS)]
    w.worst_s = 0.002
    late = [(9 * MS, 12 * MS), (20 * MS, 23 * MS)]  # the second: no stall over it
    assert Trial({}, {}, late[:1], w).spoiled_by_the_host()
    assert not Trial({}, {}, late, w).spoiled_by_the_host()
    assert Trial({}, {}, late, w, steal_s=0.01).spoiled_by_the_host()
    assert not Trial({}, {}, [], w, steal_s=0.5).spoiled_by_the_host()


def test_the_one_rule_of_a_spoiled_run() -> None:
    """Late replies (or requests never answered) are the host's when the watch explains
    each of them or the run had steal time; a run with none is not spoiled whatever the
    steal time, and one unexplained late reply without steal time is the daemon's."""
    from tests.support.stall import spoiled

    assert spoiled(0.0, 2, 2)
    assert not spoiled(0.0, 2, 1)
    assert spoiled(0.01, 2, 0)
    assert not spoiled(0.5, 0, 0)


def test_the_watch_counts_the_steal_time_of_its_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """``StallWatch.steal_s``: the steal time all CPUs gained between entering and leaving
    the watch, in seconds to 10 ms (the kernel's tick)."""
    from ecatsim.bench import stallwatch

    readings = iter([[1.0, 2.0], [1.25, 2.5]])
    monkeypatch.setattr(stallwatch, "steal_seconds", lambda: next(readings))
    monkeypatch.setattr(stallwatch, "build_c", lambda src, out: out)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set())
    with stallwatch.StallWatch() as w:
        assert w.steal_s == 0.0
    assert w.steal_s == 0.75


def test_a_kickcat_run_is_clean_when_kickcat_completed_within_the_wide_guard() -> None:
    """KickCAT judged each frame it waited for; the capture's late replies are a wide guard:
    one in LATE_GUARD passes, one more fails, and so does an unanswered request or a result
    other than the expected one."""
    from tests.support.kickcat import LATE_GUARD, Trial

    w = StallWatch()
    done = {"ok": True, "stage": "done"}
    frames = 2 * LATE_GUARD
    two = [(k * MS, k * MS + 3 * MS) for k in range(2)]
    assert Trial(done, {"frames": frames, "unpaired": 0}, two, w).clean(done)
    assert not Trial(done, {"frames": frames, "unpaired": 0}, [*two, two[0]], w).clean(done)
    assert not Trial(done, {"frames": frames, "unpaired": 1}, [], w).clean(done)
    assert not Trial({"ok": False}, {"frames": frames, "unpaired": 0}, [], w).clean(done)
