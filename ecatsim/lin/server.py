"""The LIN front door: the bus of TMC211 nodes on a pty, hosted by the daemon loop.

``door_from_config`` builds it from a segment file's ``lin:`` mapping; ``ecatsim lin``
builds it from its own options. ``ecatsim ctl door lin COMMAND ...`` reaches
:meth:`LinDoor.ctl`: inspection, and the physical conditions behind the flags of TMC211
§5.2.2 (temperature, battery voltage, coil faults, charge pump, the switch on SWI).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ecatsim.clock import Clock, MonotonicClock
from ecatsim.errors import UserError
from ecatsim.lin.bus import LinBus, Pty
from ecatsim.lin.config import BusConfig, parse_bus
from ecatsim.lin.node import Node

HELP = {
    "help": "this list",
    "nodes": "every node: address, state, positions, current, flags, identifiers, OTP",
    "temp NODE CELSIUS": "chip temperature (145 °C <TW>, 155 °C <TSD>, -10 °C low warning)",
    "vbat NODE VOLTS": "battery voltage (below 8.5 V: <UV2>)",
    "ovc1|ovc2 NODE on|off": "over-current / open load in coil A or B (<OVC1>/<OVC2>, <ElDef>)",
    "cpfail NODE on|off": "charge pump failure (<CPFail>)",
    "esw NODE open|closed|auto": "the switch on SWI (auto: from the configured switch range)",
    "stops NODE LOW HIGH|none": "mechanical stops of the rotor, 1/16 micro-steps",
    "power NODE": "power-cycle the node (power-on reset, <VddReset>)",
}

_ON = {"on": True, "1": True, "true": True, "off": False, "0": False, "false": False}


class LinDoor:
    """A LIN bus of TMC211 nodes behind a pty (a :class:`~ecatsim.doors.host.FrontDoor`)."""

    def __init__(self, cfg: BusConfig, pty: Path, clock: Clock | None = None) -> None:
        self.clock = clock or MonotonicClock()
        now = self.clock.now_ns()
        nodes = [Node(nc, now) for nc in cfg.nodes]
        self.bus = LinBus(nodes, cfg.baud, now)
        self.pty = Pty(pty)

    # --- FrontDoor ---------------------------------------------------------------------

    def fds(self) -> list[int]:
        return [self.pty.fd]

    def on_ready(self, fd: int) -> None:
        data = self.pty.read()
        out = self.bus.feed(data, self.clock.now_ns())
        if out:
            self.pty.write(out)

    def service(self, now_ns: int) -> None:
        self.bus.service(now_ns)

    def deadline_ns(self) -> int | None:
        return self.bus.deadline_ns()

    def status(self) -> dict[str, Any]:
        now = self.clock.now_ns()
        p = self.bus.parser
        keys = ("name", "address", "state", "actpos", "tagpos", "current_ma", "flags")
        nodes = [{k: s[k] for k in keys} for s in (n.status(now) for n in self.bus.nodes)]
        errors = " ".join(f"{k.lower()} {v}" for k, v in p.errors.items())
        return {
            "pty": str(self.pty.link),
            "nodes": nodes,
            "frames": p.frames,
            "errors": errors,
            "timeouts": self.bus.timeouts,
        }

    def close(self) -> None:
        self.pty.close()

    # --- control -----------------------------------------------------------------------

    def node(self, key: str) -> Node:
        """A node by name, by index (0, 1, ...) or by address (0x..)."""
        nodes = self.bus.nodes
        for n in nodes:
            if n.name == key:
                return n
        try:
            v = int(key, 0)
        except ValueError:
            v = -1
        if key.lower().startswith("0x"):
            for n in nodes:
                if n.address == v:
                    return n
        elif 0 <= v < len(nodes):
            return nodes[v]
        names = ", ".join(n.name for n in nodes)
        raise ValueError(f"no node {key!r} (nodes: {names}; or an index, or an address 0x..)")

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        now = self.clock.now_ns()
        self.bus.service(now)
        if command == "help":
            return {"commands": HELP}
        if command == "nodes":
            return {"nodes": [n.status(now) for n in self.bus.nodes]}
        if command not in {k.split()[0] for k in HELP} and command not in ("ovc1", "ovc2"):
            raise ValueError(f"unknown lin command {command!r} (try: ecatsim ctl door lin help)")
        if not args:
            raise ValueError(f"lin {command}: which node? (a name, an index or an address 0x..)")
        n = self.node(args[0])
        rest = args[1:]
        if command == "power":
            n.power_on(now)
        elif command == "stops":
            n.motor.stops = _stops(rest)
        elif command in ("temp", "vbat"):
            if len(rest) != 1:
                raise ValueError(f"lin {command} NODE VALUE: one value")
            n.set_condition(command, float(rest[0]), now)
        elif command == "esw":
            value = {"open": False, "closed": True, "auto": None}
            if len(rest) != 1 or rest[0] not in value:
                raise ValueError("lin esw NODE open|closed|auto")
            n.set_condition("esw", value[rest[0]], now)
        else:  # ovc1, ovc2, cpfail
            if len(rest) != 1 or rest[0].lower() not in _ON:
                raise ValueError(f"lin {command} NODE on|off")
            n.set_condition(command, _ON[rest[0].lower()], now)
        return {"node": n.status(now)}


def _stops(rest: list[str]) -> tuple[float, float] | None:
    if rest == ["none"]:
        return None
    if len(rest) != 2:
        raise ValueError("lin stops NODE LOW HIGH (1/16 micro-steps), or none")
    lo, hi = float(rest[0]), float(rest[1])
    if lo > hi:
        raise ValueError(f"lin stops: LOW {lo:g} is above HIGH {hi:g}")
    return lo, hi


def door_from_config(data: dict[str, object], src: str, base: Path | None) -> LinDoor:
    """The segment file's ``lin:`` mapping as a front door (ecatsim/doors/from_config.py)."""
    cfg = parse_bus(data, src, base, "lin.")
    if cfg.pty is None:
        raise UserError(
            f"{src}: lin.pty: missing: give the path where the bus's pty is linked, "
            "e.g. 'pty: /tmp/lin0'"
        )
    return LinDoor(cfg, cfg.pty)
