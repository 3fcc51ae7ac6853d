"""Private network namespaces joined by a veth pair, and the daemon run in one of them.

- :class:`NetnsPair` makes two namespaces (master, slave) with unique names and a veth
  pair between them, IPv6 off (no router-solicitation noise on the wire), everything up.
  Both namespaces are removed on exit, even after a failure, and at interpreter exit as a
  safety net.
- :func:`in_netns` switches the *calling thread* into a namespace (``setns(2)``), so a
  pysoem master can open its raw socket there: the socket stays in that namespace.
- :class:`ExtraNetns`, :func:`add_veth` and :class:`Port` for topologies of several
  daemons (chained daemons: ``ecatsim bench --bringup N --chain K``).
- :class:`Daemon` runs ``python -m ecatsim run --iface <slave end>`` inside the slave
  namespace and waits for its ``ready`` log event.

The benchmark and the real-master tests share this module (the tests add their own
helpers in tests/integration/netns.py). Ref: ip-netns(8), setns(2), veth(4).
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

CLONE_NEWNET = 0x40000000
NETNS_DIR = Path("/run/netns")
READY_TIMEOUT = 10.0
STOP_TIMEOUT = 5.0


class _Names:
    """The namespaces this process made and has not removed yet, and the counter that
    makes their names unique. One per process (:data:`NAMES`): the interpreter-exit safety
    net must find every namespace, whichever object made it."""

    def __init__(self) -> None:
        self._counter = itertools.count()
        self._lock = threading.Lock()
        self._live: set[str] = set()
        atexit.register(self.remove_all)

    def next(self) -> int:
        return next(self._counter)

    def add(self, ns: str) -> None:
        """Create namespace ``ns`` (recorded first: removed at exit even if this fails),
        IPv6 off before any interface exists in it (a veth inherits 'default')."""
        with self._lock:
            self._live.add(ns)
        ip("netns", "add", ns)
        sysctl_in(ns, "net.ipv6.conf.default.disable_ipv6", "1")
        sysctl_in(ns, "net.ipv6.conf.all.disable_ipv6", "1")

    def remove(self, ns: str) -> None:
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, check=False, timeout=10)
        with self._lock:
            self._live.discard(ns)

    def remove_all(self) -> None:
        with self._lock:
            left = list(self._live)
        for ns in left:
            self.remove(ns)


#: the process's namespaces (see :class:`_Names`)
NAMES = _Names()


def is_root() -> bool:
    return os.geteuid() == 0


def ip(*args: str) -> None:
    """Run ``ip ARGS``; a failure raises with its stderr."""
    r = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10, check=False)
    if r.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)} failed ({r.returncode}): {r.stderr.strip()}")


def netns_exists(ns: str) -> bool:
    return (NETNS_DIR / ns).exists()


def unique_tag() -> str:
    """Six hex digits, different for each call in this process (interface names)."""
    return f"{(os.getpid() * 4099 + NAMES.next() * 40503) & 0xFFFFFF:06x}"


class NetnsPair:
    """Two namespaces (``master_ns``, ``slave_ns``) with a veth pair between them.

    ``master_if`` lives in ``master_ns`` and ``slave_if`` in ``slave_ns``. Namespace names
    are ``ecs-<pid>-<n>-m`` / ``-s``; interface names are ``vm<6 hex>`` / ``vs<6 hex>``
    (IFNAMSIZ allows 15 characters; a TAP ``tap<6 hex>`` also fits). The interfaces are
    created directly inside the fresh namespaces, so their names cannot clash with anything.
    """

    def __init__(self) -> None:
        if not is_root():
            raise PermissionError(
                "NetnsPair needs root (ip netns add, veth): run the tests with sudo"
            )
        self.master_ns = ""
        self.slave_ns = ""
        self.master_if = ""
        self.slave_if = ""

    def _names(self) -> None:
        pid = os.getpid()
        n = NAMES.next()
        tag = f"{(pid * 4099 + n * 40503) & 0xFFFFFF:06x}"
        self.master_ns = f"ecs-{pid}-{n}-m"
        self.slave_ns = f"ecs-{pid}-{n}-s"
        self.master_if = f"vm{tag}"
        self.slave_if = f"vs{tag}"

    def __enter__(self) -> NetnsPair:
        try:
            self._create()
        except BaseException:
            self._remove()
            raise
        return self

    def _create(self) -> None:
        for _attempt in range(100):
            self._names()
            # a stale namespace of a killed earlier run with the same pid: take the next n
            if not netns_exists(self.master_ns) and not netns_exists(self.slave_ns):
                break
        else:
            raise RuntimeError("no free namespace name: remove stale ones ('ip netns list')")
        for ns in (self.master_ns, self.slave_ns):
            NAMES.add(ns)
        ip(
            "link", "add", self.master_if, "netns", self.master_ns, "type", "veth",
            "peer", "name", self.slave_if, "netns", self.slave_ns,
        )  # fmt: skip
        for ns, dev in ((self.master_ns, self.master_if), (self.slave_ns, self.slave_if)):
            sysctl_in(ns, f"net.ipv6.conf.{dev}.disable_ipv6", "1")
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", ns, "link", "set", dev, "up")

    def _remove(self) -> None:
        for ns in (self.master_ns, self.slave_ns):
            if ns:
                NAMES.remove(ns)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._remove()

    def exists(self) -> bool:
        """True if either namespace still exists."""
        return netns_exists(self.master_ns) or netns_exists(self.slave_ns)

    def __repr__(self) -> str:
        return f"NetnsPair({self.master_ns}:{self.master_if} <-> {self.slave_ns}:{self.slave_if})"


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


def sysctl_in(ns: str, key: str, value: str) -> None:
    """Write a net sysctl inside ``ns`` (ignored if absent, e.g. IPv6 compiled out).

    /proc/sys/net is resolved against the network namespace of the thread that opens it.
    """
    path = "/proc/sys/" + key.replace(".", "/")
    with in_netns(ns), contextlib.suppress(OSError), open(path, "w") as f:
        f.write(value)


def _setns(fd: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"setns(CLONE_NEWNET): {os.strerror(err)}")


@contextlib.contextmanager
def in_netns(ns: str) -> Iterator[None]:
    """Run the block with the calling thread in network namespace ``ns``.

    Sockets created inside stay in that namespace after the block ends. Only this thread
    moves; threads that already exist are unaffected, while threads and subprocesses
    *started inside the block* inherit the namespace (clone(2)).
    """
    try:
        target = os.open(NETNS_DIR / ns, os.O_RDONLY | os.O_CLOEXEC)
    except FileNotFoundError:
        raise RuntimeError(f"network namespace {ns!r} does not exist") from None
    try:
        own = os.open("/proc/thread-self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
        try:
            _setns(target)
            try:
                yield
            finally:
                _setns(own)
        finally:
            os.close(own)
    finally:
        os.close(target)


def is_ready_line(line: str) -> bool:
    """A log line announcing that the daemon serves frames (JSON or console format)."""
    line = line.strip()
    if line.startswith("{"):
        try:
            event = json.loads(line).get("event")
        except (ValueError, AttributeError):
            event = None
        if event is not None:
            return str(event) == "ready"
    return re.search(r"\bready\b", line) is not None


class SlaveEnd(Protocol):
    """Where a :class:`Daemon` runs: a namespace and its interface (a :class:`NetnsPair`
    has both)."""

    @property
    def slave_ns(self) -> str: ...

    @property
    def slave_if(self) -> str: ...


class DaemonFailed(RuntimeError):
    """The daemon exited before it was ready, or was not ready in time (the log in the
    message)."""


class Daemon:
    """``python -m ecatsim run --iface <slave_if> [args]`` inside the slave namespace.

    Output (stdout and stderr) goes to ``log``. ``start`` waits for the ``ready`` event and
    calls :meth:`fail` with the log if the process dies or is not ready in time. ``--log-format
    json`` is added unless ``args`` choose a format.
    """

    def __init__(self, pair: SlaveEnd, args: Sequence[str], log: Path) -> None:
        self.pair = pair
        self.args = tuple(args)
        self.log = log
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0

    def fail(self, message: str) -> None:
        """A start that failed (the tests' harness fails the test instead)."""
        raise DaemonFailed(message)

    @property
    def command(self) -> list[str]:
        fmt = [] if "--log-format" in self.args else ["--log-format", "json"]
        return [
            "ip", "netns", "exec", self.pair.slave_ns,
            sys.executable, "-m", "ecatsim", "run", "--iface", self.pair.slave_if,
            *fmt, *self.args,
        ]  # fmt: skip

    def _this_run(self) -> list[str]:
        """Log lines of the current start (after its marker line)."""
        text = self.log.read_text(errors="replace")
        marker = f"--- start {self.starts}:"
        return text[text.rfind(marker) :].splitlines()[1:]

    def last_event(self, name: str) -> dict[str, Any]:
        """The last JSON log line of the current start whose ``event`` is ``name``; {} if
        there is none (the daemon was killed, or logs in another format)."""
        for line in reversed(self._this_run()):
            try:
                event = json.loads(line)
            except ValueError:
                continue
            if isinstance(event, dict) and event.get("event") == name:
                return event
        return {}

    def start(self, timeout: float = READY_TIMEOUT) -> None:
        if self.alive():
            raise RuntimeError("daemon already running: stop() it first")
        self.starts += 1
        cmd = self.command
        with open(self.log, "ab") as f:
            f.write(f"--- start {self.starts}: {' '.join(cmd)}\n".encode())
            f.flush()
            self.proc = subprocess.Popen(
                cmd, stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.STDOUT
            )
        deadline = time.monotonic() + timeout
        while True:
            if any(is_ready_line(line) for line in self._this_run()):
                return
            if self.proc.poll() is not None:
                rc = self.proc.returncode
                self.proc = None
                self.fail(f"daemon exited with {rc} before it was ready:\n{self.log.read_text()}")
                return
            if time.monotonic() > deadline:
                self.stop()
                self.fail(f"daemon not ready after {timeout} s:\n{self.log.read_text()}")
                return
            time.sleep(0.02)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def stop(self, timeout: float = STOP_TIMEOUT) -> int | None:
        """SIGTERM, wait up to ``timeout`` s, then SIGKILL. The exit status, or None if it
        was not started. A status < 0 is the signal that ended it (-9: it had to be killed).
        """
        if self.proc is None:
            return None
        proc = self.proc
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout)
        self.proc = None
        if proc.returncode != 0 or "--user" in self.args:
            self._remove_left_socket()  # a clean exit as root removes its own
        return proc.returncode

    def _remove_left_socket(self) -> None:
        """A daemon killed with SIGKILL, or one that dropped root (--user) and so may not
        write /run/ecatsim, leaves its control socket behind; the next daemon on the link
        would replace it, but a run leaves nothing behind."""
        from ecatsim.ctl.server import default_path, run_dir

        for lock in run_dir().glob(f"iface-{self.pair.slave_if}@*.lock"):
            lock.unlink(missing_ok=True)  # the link's lock file (decision O1)
        if "--ctl" in self.args:
            return  # the caller chose the path
        default_path(self.pair.slave_if).unlink(missing_ok=True)

    def restart(self, timeout: float = READY_TIMEOUT) -> None:
        self.stop()
        self.start(timeout)
