"""One daemon per link: a lock file per interface, TAP device or UDP port in the run
directory, held (``flock``) for the daemon's life and holding its PID.

Two daemons on one interface would both answer every frame: the master sees each reply
twice. A second ``ecatsim run`` on a link that one serves is refused with one line naming
the PID that serves it (decision O1). The kernel drops the lock when the process ends, so
a daemon that was killed leaves nothing that refuses the next one.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from ecatsim.errors import UserError


def _netns() -> str:
    """The network namespace's inode: the same interface name in two namespaces is two
    links."""
    try:
        return str(os.stat("/proc/self/ns/net").st_ino)
    except OSError:
        return "0"


def lock_name(kind: str, name: str) -> str:
    """The lock file's name for ``--iface``/``--tap`` NAME or ``--udp`` PORT."""
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    return f"{kind}-{safe}@{_netns()}.lock"


class LinkLock:
    """The held lock of one link; :meth:`close` releases it and removes the file."""

    def __init__(self, path: Path, what: str) -> None:
        """Take the lock at ``path`` or raise :class:`UserError` naming the PID holding it;
        ``what`` names the link as the user gave it (``--iface ecat1``)."""
        self.path = path
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        while True:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise UserError(
                    f"{what}: ecatsim PID {pid} serves this link already; two daemons on one "
                    f"link would both answer every frame: stop that one first (kill {pid})"
                ) from None
            except BaseException:
                os.close(fd)
                raise
            try:
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:  # the daemon before removed it as we opened it
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self.fd: int | None = fd

    def close(self) -> None:
        """Remove the file, then release the lock (a daemon that opened the removed file
        meanwhile sees it gone and opens a new one)."""
        if self.fd is None:
            return
        try:
            self.path.unlink()
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None


def lock_link(
    run_dir: Path, iface: str | None, tap: str | None, udp_port: int | None
) -> LinkLock | None:
    """The lock of the link ``ecatsim run`` is about to open; None for ``--udp HOST:0``
    (the kernel picks a free port)."""
    if iface:
        return LinkLock(run_dir / lock_name("iface", iface), f"--iface {iface}")
    if tap:
        return LinkLock(run_dir / lock_name("tap", tap), f"--tap {tap}")
    if udp_port:
        return LinkLock(run_dir / lock_name("udp", str(udp_port)), f"--udp port {udp_port}")
    return None
