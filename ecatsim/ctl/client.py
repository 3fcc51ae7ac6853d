"""A small client for test suites: a running daemon's slaves through its control socket.

```python
import ecatsim.ctl.client

with ecatsim.ctl.client.connect("ecat1") as bus:      # the daemon serving --iface ecat1
    bus.slave(2).pd["Channel 1"] = 1               # set an input (name or "0x6000:01")
    assert bus.slave(2).pd["0x7000:01"] == 0       # read an output the master wrote
    print(bus.slave(2).pd.items())                 # every mapped entry with its value
    print(bus.slave(0).state)                      # AL state name
```

Every refusal is a ``ClientError`` with the daemon's one-line reason.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

from ecatsim.ctl.server import default_path, find_socket, request
from ecatsim.ctl.table import al_state_text
from ecatsim.errors import UserError


class ClientError(RuntimeError):
    """The daemon refused a request (its reason is the message)."""


class Bus:
    """One daemon's segment."""

    def __init__(self, path: Path, timeout: float = 2.0) -> None:
        self.path = path
        self.timeout = timeout

    def call(self, **req: Any) -> dict[str, Any]:
        """One control request; its answer, or ClientError."""
        try:
            reply = request(self.path, req, self.timeout)
        except UserError as exc:
            raise ClientError(str(exc)) from exc
        if not reply.get("ok"):
            raise ClientError(str(reply.get("error")))
        return reply

    def status(self) -> dict[str, Any]:
        return self.call(cmd="status")

    def slave(self, position: int) -> Slave:
        return Slave(self, position)

    def close(self) -> None:
        """Nothing held between requests: each is one datagram."""

    def __enter__(self) -> Bus:
        return self

    def __exit__(
        self,
        typ: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class ProcessData:
    """A slave's mapped entries: ``pd[ENTRY]`` reads, ``pd[ENTRY] = v`` sets an input."""

    def __init__(self, bus: Bus, position: int) -> None:
        self.bus = bus
        self.position = position

    def __getitem__(self, entry: str) -> Any:
        return self.bus.call(cmd="pd", slave=self.position, entry=entry)["value"]

    def __setitem__(self, entry: str, value: int) -> None:
        self.bus.call(cmd="pd", slave=self.position, entry=entry, value=value)

    def entries(self) -> list[dict[str, Any]]:
        """Every mapped entry: entry, name, pdo, direction, bits, value."""
        entries: list[dict[str, Any]] = self.bus.call(cmd="pd", slave=self.position)["entries"]
        return entries

    def items(self) -> list[tuple[str, Any]]:
        return [(e["entry"], e["value"]) for e in self.entries()]

    def __iter__(self) -> Iterator[str]:
        return iter(e["entry"] for e in self.entries())


class Slave:
    """One slave of the segment, by position."""

    def __init__(self, bus: Bus, position: int) -> None:
        self.bus = bus
        self.position = position
        self.pd = ProcessData(bus, position)

    @property
    def state(self) -> str:
        """The AL state (``OP``, ``SAFEOP+ERR``, ...)."""
        s = self.bus.status()["slaves"][self.position]
        return al_state_text(int(s["al_status"]))

    def od(self, index: int, sub: int = 0, value: int | str | None = None) -> Any:
        """An object dictionary value (set from the application side when ``value``)."""
        req: dict[str, Any] = {"cmd": "od", "slave": self.position, "index": index, "sub": sub}
        if value is not None:
            req["value"] = value
        return self.bus.call(**req)["value"]


def connect(link: str | None = None, *, socket: str | Path | None = None) -> Bus:
    """The daemon serving ``link`` (its --iface/--tap/--udp), or the one at ``socket``
    (its --ctl), or the only one running."""
    if socket is not None:
        return Bus(Path(socket))
    if link is not None:
        return Bus(default_path(link))
    try:
        return Bus(find_socket())
    except UserError as exc:
        raise ClientError(str(exc)) from exc
