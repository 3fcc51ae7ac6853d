"""The real-master tests' network namespaces: the benchmark's harness
(:mod:`ecatsim.bench.netns`: :class:`NetnsPair`, :func:`in_netns`, :class:`Daemon`) with
what only the tests need.

- :class:`Daemon` fails the test (with the daemon's log) when the daemon does not start;
- :func:`require_root` skips without root locally and fails in CI;
- :func:`proc_status` reads a daemon's ``/proc/PID/status``.

Ref: ip-netns(8), setns(2), veth(4).
"""

from __future__ import annotations

import os

import pytest

from ecatsim.bench import netns as harness
from ecatsim.bench.netns import (
    ExtraNetns,
    NetnsPair,
    Port,
    add_veth,
    in_netns,
    is_root,
    netns_exists,
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


def proc_status(pid: int) -> dict[str, str]:
    """The fields of ``/proc/PID/status`` (capabilities, user ids) of a daemon. Ref: proc(5)."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            k, _, v = line.partition(":")
            out[k] = v.strip()
    return out
