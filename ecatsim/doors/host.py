"""Front doors besides EtherCAT: the TMCL and LIN servers, hosted in one event loop.

A front door owns a changing set of descriptors (a listening socket, its clients, a pty)
and a simulated machine it advances on the loop's clock. :class:`DoorHost` puts all doors
behind one epoll descriptor, so the EtherCAT daemon waits on a fixed set of descriptors
and learns with one wake-up that some door has work. :func:`serve_doors` is the loop of a
daemon that serves only front doors (``ecatsim tmcl``, ``ecatsim lin``).
Another bus is another front door: ``ecatsim ctl`` sees every device.
"""

from __future__ import annotations

import select
from collections.abc import Callable
from typing import Any, Protocol

import structlog

log = structlog.get_logger("ecatsim.doors.host")

#: the longest a doors-only loop sleeps when no door has a deadline
IDLE_TIMEOUT_NS = 200_000_000


class FrontDoor(Protocol):
    """What the loop needs of a TMCL or LIN server."""

    def fds(self) -> list[int]:
        """The descriptors to wait on now (they may change after each call below)."""
        ...

    def on_ready(self, fd: int) -> None:
        """``fd`` is readable: read and answer what came."""
        ...

    def service(self, now_ns: int) -> None:
        """Advance the simulated devices to ``now_ns`` (host monotonic)."""
        ...

    def deadline_ns(self) -> int | None:
        """The next time the door needs :meth:`service`, or None."""
        ...

    def status(self) -> dict[str, Any]:
        """The door's devices for ``ecatsim ctl status``."""
        ...

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        """A control-socket request addressed to this door."""
        ...

    def close(self) -> None: ...


class DoorHost:
    """Several front doors behind one epoll descriptor."""

    def __init__(self, doors: dict[str, FrontDoor]) -> None:
        #: the doors by name, as the segment YAML and ``ctl`` name them (``tmcl``, ``lin``)
        self.doors = doors
        self._ep = select.epoll()
        self._owner: dict[int, FrontDoor] = {}
        self.failures = 0
        self._sync()

    def fileno(self) -> int:
        return self._ep.fileno()

    def _sync(self) -> None:
        """Register the descriptors the doors want now; forget the ones they closed.

        A door may close a descriptor and get the same number back for a new one before
        this runs: closing removed the old one from epoll, so every wanted descriptor is
        registered again (an existing registration is left as it is)."""
        want: dict[int, FrontDoor] = {}
        for door in self.doors.values():
            for fd in door.fds():
                want[fd] = door
        for fd in set(self._owner) - set(want):
            try:
                self._ep.unregister(fd)
            except OSError:  # closed already: epoll dropped it
                pass
        for fd in want:
            try:
                self._ep.register(fd, select.EPOLLIN)
            except FileExistsError:
                pass
        self._owner = want

    def serve(self) -> None:
        """Handle every ready descriptor (no waiting)."""
        for fd, _ in self._ep.poll(0):
            door = self._owner.get(fd)
            if door is None:
                continue
            self._guard(door.on_ready, fd)
        self._sync()

    def service(self, now_ns: int) -> None:
        """Advance every door's devices to ``now_ns``."""
        for door in self.doors.values():
            self._guard(door.service, now_ns)
        self._sync()

    def next_deadline(self) -> int | None:
        ds = [d for d in (door.deadline_ns() for door in self.doors.values()) if d is not None]
        return min(ds) if ds else None

    def status(self) -> dict[str, Any]:
        return {name: door.status() for name, door in self.doors.items()}

    def _guard(self, fn: Callable[[int], None], arg: int) -> None:
        """A door never takes the loop down: count, log once per kind, go on."""
        try:
            fn(arg)
        except Exception as exc:
            self.failures += 1
            if self.failures == 1 or self.failures % 1000 == 0:
                log.error("door_failure", error=repr(exc), count=self.failures, exc_info=exc)

    def close(self) -> None:
        for door in self.doors.values():
            door.close()
        self._ep.close()


def serve_doors(
    host: DoorHost,
    now_ns: Callable[[], int],
    stop: Callable[[], bool],
    others: dict[int, Callable[[], None]] | None = None,
) -> None:
    """The loop of a daemon that serves only front doors, until ``stop()`` is true.

    ``others``: further descriptors that end a wait (a wake-up pipe, a control socket)
    with the handler to call when one is readable."""
    others = others or {}
    watch = [host.fileno(), *others]
    while not stop():
        deadline = host.next_deadline()
        timeout_ns = IDLE_TIMEOUT_NS if deadline is None else max(0, deadline - now_ns())
        ready, _, _ = select.select(watch, (), (), min(timeout_ns, IDLE_TIMEOUT_NS) / 1e9)
        for fd in ready:
            if fd == host.fileno():
                host.serve()
            else:
                others[fd]()
        host.service(now_ns())
