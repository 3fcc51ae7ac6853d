"""Fixtures for real-master tests: a namespace pair, the daemon in one, pysoem in the other.

Every test in this directory is marked ``integration``. Without root these tests cannot
run: locally they are skipped with the reason; in CI (``CI`` set) they fail, never skip.

Usage::

    def test_something(daemon_factory, master_factory):
        daemon = daemon_factory("--slaves", "2")   # ecatsim run in the slave namespace
        master = master_factory()                  # pysoem.Master opened in the master ns
        assert master.config_init() == 2
        daemon.restart()
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.integration.netns import Daemon, NetnsPair, in_netns, require_root

HERE = Path(__file__).resolve().parent

DaemonFactory = Callable[..., Daemon]
MasterFactory = Callable[[], Any]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test collected from this directory ``integration``."""
    for item in items:
        if HERE in item.path.resolve().parents:
            item.add_marker(pytest.mark.integration)


@pytest.fixture(autouse=True)
def _integration_needs_root() -> None:
    """Skip locally without root; fail loudly in CI."""
    require_root("integration test")


@pytest.fixture
def netns_pair() -> Iterator[NetnsPair]:
    """A fresh master/slave namespace pair with a veth between them (removed afterwards)."""
    with NetnsPair() as pair:
        yield pair


@pytest.fixture
def daemon_factory(netns_pair: NetnsPair, tmp_path: Path) -> Iterator[DaemonFactory]:
    """``daemon_factory(*args) -> Daemon``: start ``ecatsim run --iface <slave_if> *args``
    in the slave namespace and wait until it is ready. Stopped at teardown; a daemon that
    does not exit with 0 on SIGTERM fails the test (with its log)."""
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
        pytest.fail("\n".join(failed), pytrace=False)


@pytest.fixture
def master_factory(netns_pair: NetnsPair) -> Iterator[MasterFactory]:
    """``master_factory() -> pysoem.Master``: a master opened on ``master_if`` inside the
    master namespace (its raw socket stays there). Closed at teardown."""
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
