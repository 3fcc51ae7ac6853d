"""The daemon loop's sleep: it wakes at the next SYNC0 deadline to the microsecond.

poll(2) counts its timeout in whole milliseconds and would wake the loop up to 1 ms late,
so pulses were handled in front of the next frame's reply (decision P1).
"""

from __future__ import annotations

import select
from typing import Any

import pytest

from tests.perf.hotpath import MS, CspCycle


def sleeps(monkeypatch: pytest.MonkeyPatch, c: CspCycle) -> list[float]:
    """Run the real loop once; return the timeouts it slept with."""
    seen: list[float] = []

    def fake_select(r: Any, w: Any, x: Any, timeout: float) -> tuple[list[int], ...]:
        seen.append(timeout)
        c.daemon.stop()
        return [], [], []

    monkeypatch.setattr(select, "select", fake_select)  # the module the daemon calls
    monkeypatch.setattr(c.link, "fileno", lambda: c.daemon._wake_r)  # something to watch
    c.daemon.run()
    return seen


@pytest.mark.parametrize("before_ns", [300_000, 1_500, 999_999])
def test_sleeps_until_the_sync0_deadline_exactly(
    monkeypatch: pytest.MonkeyPatch, before_ns: int
) -> None:
    c = CspCycle(1)
    deadline = c.seg.schedule.next_deadline()
    assert deadline is not None
    c.clock.t = deadline - before_ns
    assert sleeps(monkeypatch, c)[0] == pytest.approx(before_ns * 1e-9, abs=1e-12)


def test_a_due_pulse_means_no_sleep(monkeypatch: pytest.MonkeyPatch) -> None:
    c = CspCycle(1)
    deadline = c.seg.schedule.next_deadline()
    assert deadline is not None
    c.clock.t = deadline + MS // 10
    assert sleeps(monkeypatch, c)[0] == 0.0
