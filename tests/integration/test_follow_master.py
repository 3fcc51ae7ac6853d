"""The daemon runs on the CPU the master's frames come from (decision K5): pysoem sends from
one CPU, then from another, and the daemon's CPU set follows; with --no-follow-master-cpu or
--cpu it stays as it was. Ref: decision K5."""

from __future__ import annotations

import json
import os
import time
from typing import Any

import pysoem
import pytest

pytestmark = pytest.mark.integration


def exchange_from(cpu: int, m: Any, seconds: float = 0.1) -> None:
    """Read slave 0's AL status (FPRD) from ``cpu`` for ``seconds``. A reply late on a busy
    host (a daemon with --no-rt) is no matter here: the frames reach the daemon anyway."""
    os.sched_setaffinity(0, {cpu})
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            m.slaves[0]._fprd(0x0130, 2)
        except pysoem.WkcError:
            pass
        time.sleep(0.001)


def cpus_of(d: Any) -> set[int]:
    return os.sched_getaffinity(d.pid)


@pytest.fixture
def two_cpus() -> Any:
    allowed = os.sched_getaffinity(0)
    cpus = sorted(allowed)
    if len(cpus) < 2:
        pytest.fail(f"the follow test needs two CPUs (this process may use {cpus})")
    yield cpus[0], cpus[1]
    os.sched_setaffinity(0, allowed)


def test_the_daemon_follows_the_master_cpu(
    master_factory: Any, daemon_factory: Any, two_cpus: tuple[int, int]
) -> None:
    a, b = two_cpus
    d = daemon_factory()
    m = master_factory()
    os.sched_setaffinity(0, {b})
    assert m.config_init() == 1
    for cpu in (b, a, b):
        exchange_from(cpu, m)
        assert cpus_of(d) == {cpu}
    assert d.stop() == 0
    log = [json.loads(ln) for ln in d.log.read_text().splitlines() if ln.startswith("{")]
    assert [e["cpu"] for e in log if e["event"] == "following_master_cpu"][:1] == [b]
    assert [e["cpu_moves"] for e in log if e["event"] == "stopped"] == [3]


@pytest.mark.parametrize("flag", [["--no-follow-master-cpu"], ["--cpu", "first"], ["--no-rt"]])
def test_the_daemon_stays_where_it_is_told(
    master_factory: Any, daemon_factory: Any, two_cpus: tuple[int, int], flag: list[str]
) -> None:
    a, b = two_cpus
    flag = [str(a) if f == "first" else f for f in flag]
    d = daemon_factory(*flag)
    before = cpus_of(d)
    m = master_factory()
    assert m.config_init() == 1
    exchange_from(b, m)
    assert cpus_of(d) == before == ({a} if "--cpu" in flag else os.sched_getaffinity(1))
