"""The daemon's scheduling class: SCHED_FIFO 20 by default where allowed, off with --no-rt."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from ecatsim.errors import UserError
from ecatsim.ethercat import realtime
from tests.integration.netns import require_root


@pytest.mark.parametrize(
    ("rt", "no_rt", "busy", "cpu", "want"),
    [
        (None, False, False, None, realtime.DEFAULT_PRIORITY),  # blocking: real-time by default
        (None, True, False, None, None),  # --no-rt
        (45, False, False, None, 45),  # --rt-priority
        (None, False, True, None, None),  # busy-poll spins: not real-time unless asked
        (30, False, True, 1, 30),  # asked, and pinned
    ],
)
def test_choose_priority(
    rt: int | None, no_rt: bool, busy: bool, cpu: int | None, want: int | None
) -> None:
    assert realtime.choose_priority(rt, no_rt, busy, cpu) == want


def test_contradictions_are_one_line_errors() -> None:
    with pytest.raises(UserError, match="--no-rt and --rt-priority exclude each other"):
        realtime.choose_priority(20, True, False, None)
    with pytest.raises(UserError, match="needs --cpu N"):
        realtime.choose_priority(20, False, True, None)


def _refuse(pid: int, policy: int, param: os.sched_param) -> None:
    raise PermissionError(1, "Operation not permitted")


def test_without_the_capability_the_default_warns_and_goes_on(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(os, "sched_setscheduler", _refuse)
    assert realtime.set_fifo(20, explicit=False) is False
    assert "realtime_unavailable" in capsys.readouterr().out


def test_without_the_capability_an_explicit_priority_is_an_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(os, "sched_setscheduler", _refuse)
    with pytest.raises(UserError, match=r"--rt-priority 40: cannot set SCHED_FIFO"):
        realtime.set_fifo(40, explicit=True)


def test_fifo_taken_where_allowed() -> None:
    """Run in a child so the test process keeps its own scheduler."""
    require_root("SCHED_FIFO")
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        ok = realtime.set_fifo(20, explicit=True)
        good = ok and os.sched_getscheduler(0) == os.SCHED_FIFO
        good = good and os.sched_getparam(0).sched_priority == 20
        os._exit(0 if good and realtime.lock_memory() else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0


def test_the_cpu_latency_request_is_written_and_held(tmp_path: Path) -> None:
    """K12: 0 us as the kernel's 32-bit value, the file kept open by the caller."""
    f = tmp_path / "cpu_dma_latency"
    f.write_bytes(b"")
    fd = realtime.hold_cpu_latency(str(f))
    assert fd is not None
    try:
        assert f.read_bytes() == b"\x00\x00\x00\x00"
        os.fstat(fd)  # still open
    finally:
        os.close(fd)


def test_without_the_latency_file_one_warning_and_none(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert realtime.hold_cpu_latency(str(tmp_path / "absent")) is None
    out = capsys.readouterr().out
    assert "cpu_latency_not_held" in out
    assert "--no-hold-cpu-latency" in out
