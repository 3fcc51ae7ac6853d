"""Private network namespaces joined by a veth pair, for real-master tests.

Each pair gets unique names and is removed on exit, even after a failure (and at
interpreter exit as a safety net). ``in_netns`` switches the calling thread into a
namespace so a pysoem master can open its raw socket there.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

CLONE_NEWNET = 0x40000000
_counter = itertools.count()
_live: set[str] = set()


def _run(*args: str) -> None:
    subprocess.run(args, check=True, capture_output=True, timeout=10)


def _cleanup_all() -> None:
    for ns in list(_live):
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, check=False)
        _live.discard(ns)


atexit.register(_cleanup_all)


class NetnsPair:
    """Two namespaces (master, slave) with a veth pair between them."""

    def __init__(self) -> None:
        if os.geteuid() != 0:
            raise PermissionError("network namespaces need root")
        tag = f"{os.getpid() % 100000:05d}{next(_counter) % 1000:03d}"
        self.master_ns = f"ecs-{tag}-m"
        self.slave_ns = f"ecs-{tag}-s"
        self.master_if = f"vm{tag}"
        self.slave_if = f"vs{tag}"

    def __enter__(self) -> NetnsPair:
        try:
            for ns in (self.master_ns, self.slave_ns):
                _run("ip", "netns", "add", ns)
                _live.add(ns)
            _run(
                "ip",
                "link",
                "add",
                self.master_if,
                "netns",
                self.master_ns,
                "type",
                "veth",
                "peer",
                "name",
                self.slave_if,
                "netns",
                self.slave_ns,
            )
            for ns, dev in ((self.master_ns, self.master_if), (self.slave_ns, self.slave_if)):
                for name in (dev, "lo"):
                    subprocess.run(
                        [
                            "ip",
                            "netns",
                            "exec",
                            ns,
                            "sysctl",
                            "-q",
                            "-w",
                            f"net.ipv6.conf.{name}.disable_ipv6=1",
                        ],
                        capture_output=True,
                        check=False,
                    )
                _run("ip", "-n", ns, "link", "set", dev, "up")
                _run("ip", "-n", ns, "link", "set", "lo", "up")
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        for ns in (self.master_ns, self.slave_ns):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, check=False)
            _live.discard(ns)

    def exists(self) -> bool:
        out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
        return self.master_ns in out or self.slave_ns in out


_libc = ctypes.CDLL(None, use_errno=True)


def _setns(fd: int) -> None:
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


@contextlib.contextmanager
def in_netns(ns: str) -> Iterator[None]:
    """Run the block with the calling thread in network namespace ``ns``.

    Sockets created inside stay in that namespace after the block ends.
    """
    own = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    target = os.open(f"/run/netns/{ns}", os.O_RDONLY)
    try:
        _setns(target)
        try:
            yield
        finally:
            _setns(own)
    finally:
        os.close(target)
        os.close(own)


class Daemon:
    """``ecatsim run`` inside the slave namespace of a pair."""

    def __init__(self, pair: NetnsPair, args: tuple[str, ...], log: Path) -> None:
        self.pair = pair
        self.args = args
        self.log = log
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0

    def start(self, timeout: float = 10.0) -> None:
        self.starts += 1
        cmd = [
            "ip",
            "netns",
            "exec",
            self.pair.slave_ns,
            sys.executable,
            "-m",
            "ecatsim",
            "run",
            "--iface",
            self.pair.slave_if,
            "--log-format",
            "json",
            *self.args,
        ]
        with open(self.log, "ab") as f:
            f.write(f"--- start {self.starts}: {' '.join(cmd)}\n".encode())
        f = open(self.log, "ab")  # noqa: SIM115 - owned by the process lifetime
        self.proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)
        f.close()
        deadline = time.monotonic() + timeout
        marker = f"--- start {self.starts}:"
        while time.monotonic() < deadline:
            text = self.log.read_text(errors="replace")
            tail = text[text.rfind(marker) :]
            if '"ready"' in tail:
                return
            if self.proc.poll() is not None:
                raise RuntimeError(f"daemon exited with {self.proc.returncode}:\n{tail}")
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"daemon not ready after {timeout} s:\n{self.log.read_text()}")

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> int | None:
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        rc = self.proc.returncode
        self.proc = None
        return rc

    def restart(self) -> None:
        self.stop()
        self.start()
