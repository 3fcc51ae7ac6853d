"""Helpers for the TMCL tests: a door served by a thread on a manual clock, raw telegrams."""

from __future__ import annotations

import os
import queue
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ecatsim.clock import ManualClock
from ecatsim.doors.host import DoorHost, serve_doors
from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import ModuleConfig
from ecatsim.tmcl.server import TmclDoor


class Served:
    """A door whose loop runs in a thread; time moves only when the test says."""

    def __init__(self, door: TmclDoor, clock: ManualClock) -> None:
        self.door = door
        self.clock = clock
        self.host = DoorHost({"tmcl": door})
        self._stop = False
        self._wake_r, self._wake_w = os.pipe()
        self._calls: queue.Queue[Callable[[], Any]] = queue.Queue()
        self._results: queue.Queue[Any] = queue.Queue()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        serve_doors(self.host, self.clock.now_ns, lambda: self._stop, {self._wake_r: self._call})

    def _call(self) -> None:
        os.read(self._wake_r, 1)
        fn = self._calls.get()
        try:
            self._results.put(fn())
        except Exception as exc:
            self._results.put(exc)

    def in_loop(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` in the door's thread (between its lines' telegrams)."""
        self._calls.put(fn)
        os.write(self._wake_w, b"x")
        result = self._results.get(timeout=5)
        if isinstance(result, Exception):
            raise result
        return result

    def ctl(self, command: str, *args: str) -> dict[str, Any]:
        """``ecatsim ctl door tmcl COMMAND ARGS`` as the control socket would call it."""
        out: dict[str, Any] = self.in_loop(lambda: self.door.ctl(command, list(args)))
        return out

    @property
    def port(self) -> int:
        port: int = self.door.listeners[0].port
        return port

    @property
    def url(self) -> str:
        return f"127.0.0.1:{self.port}"

    def advance(self, seconds: float) -> None:
        """Simulated time passes (the next command sees the module at the new time)."""
        self.clock.advance(round(seconds * 1e9))

    def close(self) -> None:
        self._stop = True
        self.thread.join(5)
        self.host.close()
        os.close(self._wake_r)
        os.close(self._wake_w)


@contextmanager
def served(
    modules: list[ModuleConfig] | None = None,
    eeprom: Path | None = None,
    listen: list[str] | None = None,
    clock: ManualClock | None = None,
) -> Iterator[Served]:
    clock = clock or ManualClock(1_000_000_000)
    door = TmclDoor(
        modules or [ModuleConfig()], listen or ["tcp://127.0.0.1:0"], eeprom, clock=clock
    )
    s = Served(door, clock)
    try:
        yield s
    finally:
        s.close()


def frame(op: int, typ: int = 0, motor: int = 0, value: int = 0, address: int = 1) -> bytes:
    """A command telegram with a correct checksum."""
    return P.encode_command(address, P.Command(op, typ, motor, value))


def exchange(sock: socket.socket, data: bytes, n: int = 9) -> bytes:
    """Send ``data``, read ``n`` reply bytes."""
    sock.sendall(data)
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        if not chunk:
            raise ConnectionError(f"closed after {out!r}")
        out += chunk
    return out
