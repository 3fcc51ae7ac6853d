"""Fixtures for real-master tests: a namespace pair, the daemon in one, pysoem in the other.

Without root these tests cannot run. In CI (``CI`` set) that is an error, never a skip.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.integration.netns import Daemon, NetnsPair, in_netns


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.geteuid() == 0:
        return
    if os.environ.get("CI"):
        raise pytest.UsageError(
            "integration tests need root (network namespaces, raw sockets); CI runs as root"
        )
    skip = pytest.mark.skip(reason="needs root: network namespaces and raw sockets")
    for item in items:
        if "integration" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def netns_pair() -> Iterator[NetnsPair]:
    with NetnsPair() as pair:
        yield pair


@pytest.fixture
def daemon_factory(netns_pair: NetnsPair, tmp_path: Path) -> Iterator[Any]:
    daemons: list[Daemon] = []

    def make(*args: str) -> Daemon:
        d = Daemon(netns_pair, args, tmp_path / f"daemon{len(daemons)}.log")
        daemons.append(d)
        d.start()
        return d

    yield make
    failed = []
    for d in daemons:
        alive = d.alive()
        rc = d.stop()
        if alive and rc not in (0, None):
            failed.append(f"daemon exited with {rc} on SIGTERM:\n{d.log.read_text()}")
    if failed:
        pytest.fail("\n".join(failed))


@pytest.fixture
def master_factory(netns_pair: NetnsPair) -> Iterator[Any]:
    import pysoem

    masters: list[Any] = []

    def make() -> Any:
        m = pysoem.Master()
        with in_netns(netns_pair.master_ns):
            m.open(netns_pair.master_if)
        masters.append(m)
        return m

    yield make
    for m in masters:
        try:
            m.close()
        except Exception:
            pass
