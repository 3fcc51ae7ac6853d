"""The real-master tests' network namespaces: the benchmark's harness
(:mod:`ecatsim.bench.netns`: :class:`NetnsPair`, :func:`in_netns`, :class:`Daemon`) with
what only the tests need.

- :class:`Daemon` fails the test (with the daemon's log) when the daemon does not start;
- :func:`require_root` skips without root locally and fails in CI;
- :class:`ExtraNetns`, :func:`add_veth` and :class:`Port` for topologies of several daemons;
- :func:`proc_status` reads a daemon's ``/proc/PID/status``.

Ref: ip-netns(8), setns(2), veth(4).
"""

from __future__ import annotations

import os
from types import TracebackType

import pytest

from ecatsim.bench import netns as harness
from ecatsim.bench.netns import (
    NAMES,
    NetnsPair,
    in_netns,
    ip,
    is_root,
    netns_exists,
    sysctl_in,
    unique_tag,
)
from ecatsim.bench.netns import is_ready_line as _is_ready_line

__all__ = [
    "Daemon",
    "ExtraNetns",
    "NetnsPair",
    "Port",
    "_is_ready_line",
    "add_veth",
    "in_netns",
    "is_root",
    "netns_exists",
    "proc_status",
    "require_root",
]


def require_root(what: str = "this test") -> None:
    """Skip without root locally; fail loudly in CI (``CI`` set), never skip there."""
    if is_root():
        return
    reason = f"{what} needs root (network namespaces, veth, raw sockets)"
    if os.environ.get("CI"):
        pytest.fail(f"{reason}; CI must run the suite as root", pytrace=False)
    pytest.skip(f"{reason}: run 'sudo .venv/bin/python -m pytest'")


class Daemon(harness.Daemon):
    """The harness's daemon; a start that fails fails the test with the daemon's log."""

    def fail(self, message: str) -> None:
        pytest.fail(message, pytrace=False)


class ExtraNetns:
    """One more namespace (``ns``), removed on exit like a :class:`NetnsPair`'s, for
    topologies of several daemons; :meth:`veth` cables it to another namespace.

    Names: ``ecs-<pid>-<n>-x``; interfaces ``vx<6 hex>`` (the other end ``vy<6 hex>``)."""

    def __init__(self) -> None:
        if not is_root():
            raise PermissionError("ExtraNetns needs root (ip netns add, veth)")
        self.ns = f"ecs-{os.getpid()}-{NAMES.next()}-x"

    def __enter__(self) -> ExtraNetns:
        try:
            NAMES.add(self.ns)
            ip("-n", self.ns, "link", "set", "lo", "up")
        except BaseException:
            NAMES.remove(self.ns)
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        NAMES.remove(self.ns)

    def veth(self, other_ns: str) -> tuple[str, str]:
        """A veth pair, one end here and one in ``other_ns``, both up: (here, there)."""
        return add_veth(self.ns, other_ns)


def add_veth(ns_a: str, ns_b: str) -> tuple[str, str]:
    """A veth pair between two namespaces this process made, both ends up (removed with
    the namespaces): the names of its ends in ``ns_a`` and ``ns_b``."""
    tag = unique_tag()
    a, b = f"vx{tag}", f"vy{tag}"
    ip("link", "add", a, "netns", ns_a, "type", "veth", "peer", "name", b, "netns", ns_b)
    for ns, dev in ((ns_a, a), (ns_b, b)):
        sysctl_in(ns, f"net.ipv6.conf.{dev}.disable_ipv6", "1")
        ip("-n", ns, "link", "set", dev, "up")
    return a, b


class Port:
    """Where a :class:`Daemon` runs: a namespace and its interface (a NetnsPair has the
    same two attributes)."""

    def __init__(self, slave_ns: str, slave_if: str) -> None:
        self.slave_ns = slave_ns
        self.slave_if = slave_if


def proc_status(pid: int) -> dict[str, str]:
    """The fields of ``/proc/PID/status`` (capabilities, user ids) of a daemon. Ref: proc(5)."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            k, _, v = line.partition(":")
            out[k] = v.strip()
    return out
