"""A door on a manual clock with a line that records what the module sends."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ecatsim.clock import ManualClock
from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import Module, ModuleConfig
from ecatsim.tmcl.server import LineState, TmclDoor
from ecatsim.tmcl.transport import Line


class FakeLine(Line):
    """A line whose output is kept in ``sent`` (no descriptor)."""

    def __init__(self) -> None:
        super().__init__(-1)
        self.sent = bytearray()

    def read(self) -> bytes | None:
        return b""

    def _write(self, data: bytes) -> int:
        self.sent += data
        return len(data)

    def close(self) -> None:
        self.closed = True


class Bench:
    """Telegrams in, replies out, time on a manual clock."""

    def __init__(self, modules: list[ModuleConfig] | None = None) -> None:
        self.clock = ManualClock(1_000_000_000)
        self.door = TmclDoor(modules or [ModuleConfig()], [], None, clock=self.clock)
        self.line = FakeLine()
        self.st = LineState(self.line)
        self.door.lines[-1] = self.st  # served like a real line, never polled

    @property
    def m(self) -> Module:
        return self.door.modules[0]

    def send(self, data: bytes) -> bytes:
        """Bytes in at the current time; what the modules sent at once."""
        start = len(self.line.sent)
        self.door.receive(self.st, data, self.clock.now_ns())
        return bytes(self.line.sent[start:])

    def cmd(
        self, op: int, typ: int = 0, motor: int = 0, value: int = 0, address: int = 1
    ) -> tuple[int, int]:
        """(status, value) of one command."""
        out = self.send(P.encode_command(address, P.Command(op, typ, motor, value)))
        assert len(out) == 9, out
        assert P.checksum(out[:8]) == out[8]
        return out[2], P.to_signed(int.from_bytes(out[4:8], "big"))

    def value(self, op: int, typ: int = 0, motor: int = 0, value: int = 0) -> int:
        status, v = self.cmd(op, typ, motor, value)
        assert status == P.OK, (op, typ, motor, value, status)
        return v

    def gap(self, n: int) -> int:
        return self.value(P.GAP, n)

    def sap(self, n: int, value: int) -> None:
        assert self.cmd(P.SAP, n, 0, value)[0] == P.OK

    def advance(self, seconds: float) -> None:
        self.clock.advance(round(seconds * 1e9))
        self.door.service(self.clock.now_ns())


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench()
    yield b
    b.door.close()
