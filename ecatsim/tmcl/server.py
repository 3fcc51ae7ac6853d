"""The TMCL front door: emulated TMCM-1311 modules on RS485-style lines (TCP clients,
pseudo-terminals), for ``ecatsim tmcl`` and for the segment YAML's ``tmcl:`` key.

Every line reaches every module; a module answers the telegrams that carry its address
(global parameter 66) with its host address (76) after the telegram pause (75). A wrong
checksum is answered with status 1; telegrams for other addresses are left to the other
modules on the line (§4.1, §4.2, §10.1).

```yaml
tmcl:
  listen: [tcp://127.0.0.1:2323, pty:/tmp/tmcm1311]   # one or more lines
  eeprom: tmcl-eeprom.json     # optional: STAP/STGP persist here (relative to this file)
  modules:                     # optional: default one module at address 1
    - address: 1
      motor: {torque_per_amp: 0.4, rotor_inertia: 3.0e-5, load_inertia: 0.0,
              friction: 0.01, viscous: 0.002, load: 0.0,
              resistance: 0.75, inductance: 0.0025, supply_v: 24.0}
      switches: {left: -512000, right: 512000, home: 25600, home_width: 2560}
      analog: [0, 0]
```
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import structlog

from ecatsim.clock import Clock, MonotonicClock
from ecatsim.errors import UserError
from ecatsim.tmcl import ascii as A
from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.eeprom import Eeprom
from ecatsim.tmcl.module import Module, ModuleConfig
from ecatsim.tmcl.motor import Mechanics, Switches
from ecatsim.tmcl.protocol import Command, Framer
from ecatsim.tmcl.transport import Line, PtyLine, TcpListener, parse_listen

log = structlog.get_logger("ecatsim.tmcl")

MAX_LINES = 64


@dataclass(slots=True)
class LineState:
    """What the door keeps per line: the framer, ASCII mode, replies waiting for their
    telegram pause."""

    line: Line
    framer: Framer = field(default_factory=Framer)
    ascii: Module | None = None
    editor: A.LineEditor = field(default_factory=A.LineEditor)
    queue: list[tuple[int, bytes]] = field(default_factory=list)
    frames: int = 0


class TmclDoor:
    """Serves modules on lines; a :class:`~ecatsim.doors.host.FrontDoor`."""

    def __init__(
        self,
        modules: list[ModuleConfig],
        listen: list[str],
        eeprom: Path | None = None,
        clock: Clock | None = None,
        base: Path | None = None,
    ) -> None:
        self.clock = clock or MonotonicClock()
        self.eeprom = Eeprom(eeprom)
        now = self.clock.now_ns()
        self.modules = [
            Module(i, cfg, self.eeprom.section(i), now) for i, cfg in enumerate(modules)
        ]
        self.listeners: list[TcpListener] = []
        self.lines: dict[int, LineState] = {}
        self.bad_checksums = 0
        self.frames = 0
        self.disconnects = 0
        self._closing: list[Line] = []
        #: module index -> the line that asked for the target-reached event (138)
        self._event_line: dict[int, LineState] = {}
        try:
            for url in listen:
                kind, where, port = parse_listen(url, base)
                if kind == "tcp":
                    self.listeners.append(TcpListener(where, port))
                else:
                    self._add(PtyLine(Path(where)))
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------- FrontDoor

    def fds(self) -> list[int]:
        # a dropped line's descriptor is closed only now, when the host is about to forget
        # it: closed earlier, its number could come back from accept() while the host
        # still thinks it watches it (epoll forgets closed descriptors by itself)
        for line in self._closing:
            line.close()
        self._closing.clear()
        return [x.fileno() for x in self.listeners] + list(self.lines)

    def on_ready(self, fd: int) -> None:
        for lst in self.listeners:
            if lst.fileno() == fd:
                line = lst.accept()
                if line is not None:
                    if len(self.lines) >= MAX_LINES:
                        line.close()
                    else:
                        self._add(line)
                return
        st = self.lines.get(fd)
        if st is None:
            return
        data = st.line.read()
        if data is None:
            self._drop(st)
            return
        if data:
            self.receive(st, data, self.clock.now_ns())

    def service(self, now_ns: int) -> None:
        self._advance(now_ns)
        for idx, st in list(self._event_line.items()):
            m = self.modules[idx]
            if m.axis.reached or not m.target_event:
                if m.target_event:
                    m.target_event = False
                    self._queue(
                        st,
                        m,
                        P.encode_reply(m.host_address, m.address, P.EVENT, P.TARGET_EVENT, 1),
                        now_ns,
                    )
                del self._event_line[idx]
        for st in list(self.lines.values()):
            self._flush(st, now_ns)

    def deadline_ns(self) -> int | None:
        ds = [d for d in (m.next_deadline() for m in self.modules) if d is not None]
        for st in self.lines.values():
            if st.queue:
                ds.append(st.queue[0][0])
            if st.line.out:
                ds.append(self.clock.now_ns() + 10_000_000)
        return min(ds) if ds else None

    def status(self) -> dict[str, Any]:
        return {
            "listen": [x.url for x in self.listeners]
            + [st.line.name for st in self.lines.values() if isinstance(st.line, PtyLine)],
            "clients": sum(1 for st in self.lines.values() if not isinstance(st.line, PtyLine)),
            "frames": self.frames,
            "bad_checksums": self.bad_checksums,
            "modules": [self._module_status(m) for m in self.modules],
        }

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        from ecatsim.tmcl.ctl import handle

        self._advance(self.clock.now_ns())
        return handle(self, command, args)

    def close(self) -> None:
        for lst in self.listeners:
            lst.close()
        for st in self.lines.values():
            st.line.close()
        for line in self._closing:
            line.close()
        self._closing.clear()
        self.lines.clear()
        self.listeners.clear()

    # ------------------------------------------------------------- lines

    def _add(self, line: Line) -> None:
        st = LineState(line, Framer(line.gap_ns))
        if any(m.gp0[67] & 1 for m in self.modules):  # §4.4.4: start up in ASCII mode
            st.ascii = next(m for m in self.modules if m.gp0[67] & 1)
        self.lines[line.fileno()] = st

    def _drop(self, st: LineState) -> None:
        self.disconnects += 1
        self.lines.pop(st.line.fileno(), None)
        self._closing.append(st.line)
        for idx, ev in list(self._event_line.items()):
            if ev is st:
                del self._event_line[idx]

    def _advance(self, now_ns: int) -> None:
        for m in self.modules:
            m.advance_to(now_ns)

    def module(self, address: int) -> Module | None:
        for m in self.modules:
            if m.address == address:
                return m
        return None

    def receive(self, st: LineState, data: bytes, now_ns: int) -> None:
        """Bytes from a line at ``now_ns``."""
        self._advance(now_ns)
        if st.ascii is not None:
            self._receive_ascii(st, data, now_ns)
            return
        frames = st.framer.feed(data, now_ns)
        for i, frame in enumerate(frames):
            if st.ascii is not None:  # 139 switched the line: the rest is text
                rest = b"".join(frames[i:]) + bytes(st.framer.take())
                self._receive_ascii(st, rest, now_ns)
                return
            self._frame(st, frame, now_ns)

    def _frame(self, st: LineState, frame: bytes, now_ns: int) -> None:
        self.frames += 1
        st.frames += 1
        req = P.decode(frame)
        for m in self.modules:
            if m.address != req.address:
                continue
            if not req.checksum_ok:
                self.bad_checksums += 1
                m.errors += 1
                reply = P.encode_reply(
                    m.host_address,
                    m.address,
                    P.WRONG_CHECKSUM,
                    req.command.opcode,
                    req.command.value,
                )
                self._queue(st, m, reply, now_ns)
                continue
            self._command(st, m, req.command, now_ns)

    def _command(self, st: LineState, m: Module, cmd: Command, now_ns: int) -> None:
        addr = m.address  # the reply comes from the address the host used (SGP 66)
        r = m.execute(cmd)
        if r is None:
            return
        if r.raw is not None:
            self._queue(st, m, r.raw, now_ns)
        else:
            self._queue(
                st, m, P.encode_reply(m.host_address, addr, r.status, cmd.opcode, r.value), now_ns
            )
        if cmd.opcode == P.TARGET_EVENT and r.status == P.OK:
            self._event_line[m.index] = st
        if cmd.opcode == P.ASCII_MODE and r.status == P.OK:
            st.ascii = m

    def _receive_ascii(self, st: LineState, data: bytes, now_ns: int) -> None:
        mod = st.ascii
        assert mod is not None
        echo, lines = st.editor.feed(data, self._echo_mode)
        if echo:
            st.line.send(echo)
        for text in lines:
            parsed = A.parse(text)
            if parsed is None:
                continue
            m = self.module(parsed.address)
            if m is None:
                continue
            if parsed.special == "BIN":
                st.ascii = None
                continue
            if parsed.special is not None:
                cmd = Command(P.RUN_APP if parsed.special == "RUN" else P.STOP_APP)
                r = m.execute(cmd)
            elif parsed.error is not None:
                r = P.Reply(parsed.error, 0)
            else:
                assert parsed.command is not None
                r = m.execute(parsed.command)
            if r is None:
                continue
            self._queue(st, m, A.reply_text(m.host_address, m.address, r.status, r.value), now_ns)
            if st.ascii is None:
                return

    def _echo_mode(self, address: int) -> int | None:
        """Global parameter 67 of the module with ``address``; None: no such module."""
        m = self.module(address)
        return None if m is None else m.gp0[67]

    def _queue(self, st: LineState, m: Module, data: bytes, now_ns: int) -> None:
        """Send after the telegram pause of global parameter 75 (ms, decision T5)."""
        pause = m.gp0[75]
        if pause == 0 and not st.queue:
            st.line.send(data)
            return
        st.queue.append((now_ns + pause * 1_000_000, data))
        st.queue.sort(key=lambda q: q[0])
        self._flush(st, now_ns)

    def _flush(self, st: LineState, now_ns: int) -> None:
        while st.queue and st.queue[0][0] <= now_ns:
            st.line.send(st.queue.pop(0)[1])
        st.line.flush()
        if st.line.dead and st.line.fileno() in self.lines:
            self._drop(st)

    def _module_status(self, m: Module) -> dict[str, Any]:
        ax = m.axis
        return {
            "address": m.address,
            "mode": ("position", "velocity", "torque")[ax.mode],
            "closed_loop": ax.closed,
            "actual_position": ax.actual(),
            "target_position": ax.target,
            "actual_speed": round(ax.vel),
            "encoder": ax.encoder(),
            "rotor_usteps": round(ax.rotor),
            "target_reached": ax.reached,
            "status_word": ax.status_word(),
            "driver_errors": ax.driver_errors(),
            "deviation": ax.deviation,
            "load_nm": ax.mech.load,
            "program": ("stopped", "running", "step", "reset")[m.interp.state],
            "pc": m.interp.pc,
            "faults": [
                k
                for k in ("overtemperature", "encoder_loss", "undervoltage", "short", "stall")
                if getattr(ax.faults, k)
            ],
            "commands": m.commands,
            "errors": m.errors,
        }


# ----------------------------------------------------------------- configuration


def _err(src: str, key: str, msg: str) -> UserError:
    return UserError(f"{src}: tmcl.{key}: {msg}")


def _floats(src: str, key: str, data: object, cls: type[Mechanics] | type[Switches]) -> Any:
    if data is None:
        return cls()
    if not isinstance(data, dict):
        raise _err(src, key, "expected a mapping")
    names = {f.name for f in fields(cls)} - {"forced"}
    kw: dict[str, Any] = {}
    for k, v in data.items():
        if k not in names:
            raise _err(src, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(names))})")
        if v is None and cls is Switches:
            kw[k] = None
            continue
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise _err(src, f"{key}.{k}", f"expected a number, got {v!r}")
        if cls is Mechanics and k in _POSITIVE and not v > 0:
            raise _err(src, f"{key}.{k}", f"expected a number above 0, got {v!r}")
        if cls is Mechanics and k in _NOT_NEGATIVE and not v >= 0:
            raise _err(src, f"{key}.{k}", f"expected 0 or more, got {v!r}")
        kw[k] = float(v)
    return cls(**kw)


#: motor keys a physical machine has above zero, or at least zero
_POSITIVE = ("rotor_inertia", "supply_v", "torque_per_amp")
_NOT_NEGATIVE = ("load_inertia", "friction", "viscous", "resistance", "inductance")


def _module_config(src: str, i: int, data: object) -> ModuleConfig:
    key = f"modules[{i}]"
    if not isinstance(data, dict):
        raise _err(src, key, "expected a mapping like {address: 1}")
    allowed = {"address", "motor", "switches", "analog"}
    for k in data:
        if k not in allowed:
            raise _err(src, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(allowed))})")
    address = data.get("address", i + 1)
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 255:
        raise _err(src, f"{key}.address", f"expected 0-255, got {address!r}")
    analog = data.get("analog", [0, 0])
    if (
        not isinstance(analog, list)
        or len(analog) != 2
        or not all(isinstance(a, int) and 0 <= a <= 4095 for a in analog)
    ):
        raise _err(src, f"{key}.analog", "expected two values 0-4095, e.g. [0, 2048]")
    return ModuleConfig(
        address=address,
        mech=_floats(src, f"{key}.motor", data.get("motor"), Mechanics),
        switches=_floats(src, f"{key}.switches", data.get("switches"), Switches),
        analog=(analog[0], analog[1]),
    )


def parse_config(
    data: dict[str, object], src: str, base: Path | None
) -> tuple[list[ModuleConfig], list[str], Path | None]:
    """The ``tmcl:`` mapping: (modules, listen URLs, EEPROM file)."""
    allowed = {"listen", "eeprom", "modules"}
    for k in data:
        if k not in allowed:
            raise UserError(f"{src}: tmcl.{k}: unknown key (allowed: eeprom, listen, modules)")
    listen = data.get("listen", [])
    if isinstance(listen, str):
        listen = [listen]
    if not isinstance(listen, list) or not listen or not all(isinstance(u, str) for u in listen):
        raise _err(src, "listen", "expected one or more URLs, e.g. [tcp://127.0.0.1:2323]")
    for u in listen:
        try:
            parse_listen(u, base)
        except ValueError as exc:
            raise _err(src, "listen", str(exc)) from None
    eeprom = data.get("eeprom")
    path: Path | None = None
    if eeprom is not None:
        if not isinstance(eeprom, str):
            raise _err(src, "eeprom", "expected a file path")
        path = Path(eeprom)
        if base is not None and not path.is_absolute():
            path = base / path
    mods = data.get("modules", [{"address": 1}])
    if not isinstance(mods, list) or not mods:
        raise _err(src, "modules", "expected a list of modules, e.g. [{address: 1}]")
    configs = [_module_config(src, i, x) for i, x in enumerate(mods)]
    seen: set[int] = set()
    for i, c in enumerate(configs):
        if c.address in seen:
            raise _err(src, f"modules[{i}].address", f"{c.address} is used twice on the line")
        seen.add(c.address)
    return configs, list(listen), path


def door_from_config(data: dict[str, object], src: str, base: Path | None) -> TmclDoor:
    """The segment YAML's ``tmcl:`` mapping as a front door."""
    if not isinstance(data, dict):
        raise UserError(f"{src}: tmcl: expected a mapping")
    modules, listen, eeprom = parse_config(data, src, base)
    return TmclDoor(modules, listen, eeprom, base=base)
