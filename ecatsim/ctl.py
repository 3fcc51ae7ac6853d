"""Local control socket: status, fault injection, ESC memory peek/poke, OD read/write.

A unix datagram socket (mode 0600) carrying one JSON request and one JSON reply per
datagram. It is served by the daemon loop between frames, never inside frame processing.
"""

from __future__ import annotations

import json
import os
import socket
import struct
import tempfile
from pathlib import Path
from typing import Any

from ecatsim.device.drive import Drive
from ecatsim.doors import DoorHost
from ecatsim.errors import UserError
from ecatsim.esc import regs
from ecatsim.faults.engine import FaultEngine
from ecatsim.faults.spec import parse_fault
from ecatsim.segment import Segment

MAX_REQUEST = 4096


def run_dir() -> Path:
    """Where control sockets live: /run/ecatsim for root, else the user's runtime dir."""
    if os.geteuid() == 0:
        return Path("/run/ecatsim")
    base = os.environ.get("XDG_RUNTIME_DIR") or f"/tmp/ecatsim-{os.getuid()}"
    return Path(base) / "ecatsim"


def default_path(link: str) -> Path:
    """The control socket of the daemon serving ``link`` (interface, TAP or HOST:PORT)."""
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in link)
    return run_dir() / f"{safe}.sock"


def parse_value(text: str) -> int | float | str:
    """A ``key=value`` argument: an integer (any base), a number, or a word."""
    try:
        return int(text, 0)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


class ControlSocket:
    """The daemon side."""

    def __init__(
        self, path: Path, segment: Segment, faults: FaultEngine, doors: DoorHost | None = None
    ) -> None:
        self.path = path
        self.segment = segment
        self.faults = faults
        #: the TMCL/LIN front doors the daemon serves beside the segment
        self.doors = doors
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        if path.exists():
            _remove_stale(path)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        old = os.umask(0o177)
        try:
            self.sock.bind(str(path))
        except OSError as exc:
            raise UserError(
                f"--ctl {path}: cannot create the control socket ({exc.strerror})"
            ) from exc
        finally:
            os.umask(old)
        os.chmod(path, 0o600)
        self.sock.setblocking(False)

    def fileno(self) -> int:
        return self.sock.fileno()

    def serve(self) -> None:
        """Answer every waiting request."""
        while True:
            try:
                data, addr = self.sock.recvfrom(MAX_REQUEST)
            except BlockingIOError:
                return
            try:
                reply = self.handle(json.loads(data))
            except (ValueError, KeyError, TypeError, IndexError) as exc:
                reply = {"ok": False, "error": str(exc)}
            if addr:
                try:
                    self.sock.sendto(json.dumps(reply).encode(), addr)
                except OSError:
                    pass

    def _inject(self, fault: dict[str, Any]) -> dict[str, Any]:
        fid = self.faults.add(parse_fault(fault), self.segment.clock.now_ns())
        return {"ok": True, "id": fid}

    def _door(self, name: str, command: str, args: list[Any]) -> dict[str, Any]:
        doors = self.doors.doors if self.doors is not None else {}
        if name not in doors:
            raise ValueError(f"no front door {name!r} (serving: {', '.join(doors) or 'none'})")
        return {"ok": True, **doors[name].ctl(command, [str(a) for a in args])}

    def status(self) -> dict[str, Any]:
        """Every slave's AL state and code, DL status, error counters; the active faults.

        Ref: TMC8460 §5.19 (DL status), §5.20 (AL status), §5.34-5.38 (error counters).
        """
        out = []
        for esc in self.segment.escs:
            m = esc.mem
            al = struct.unpack_from("<HxxH", m, regs.AL_STATUS)
            out.append(
                {
                    "position": esc.position,
                    "station": struct.unpack_from("<H", m, regs.STATION_ADDRESS)[0],
                    "al_status": al[0],
                    "al_status_code": al[1],
                    "dl_status": struct.unpack_from("<H", m, regs.DL_STATUS)[0],
                    "rx_errors": [struct.unpack_from("<BB", m, 0x0300 + 2 * p) for p in (0, 1)],
                    "fwd_rx_errors": list(m[0x0308:0x030A]),
                    "pu_errors": m[0x030C],
                    "pdi_errors": m[0x030D],
                    "lost_link": list(m[0x0310:0x0312]),
                    "wd_expired": m[0x0442],
                }
            )
        seg = self.segment
        return {
            "ok": True,
            "slaves": out,
            "frames": seg.frames,
            "bad_frames": seg.bad_frames,
            "faults": self.faults.status(),
            "faults_fired": self.faults.fired_total,
            "doors": self.doors.status() if self.doors is not None else {},
        }

    def handle(self, req: dict[str, Any]) -> dict[str, Any]:
        """One request -> one reply."""
        cmd = req["cmd"]
        seg = self.segment
        now = seg.clock.now_ns()
        if cmd == "status":
            return self.status()
        if cmd == "inject":  # any fault, as in the segment YAML's faults: list
            return self._inject(dict(req["fault"]))
        if cmd == "clear":  # one fault by id, or all
            fid = req.get("id")
            return {
                "ok": True,
                "cleared": self.faults.clear(None if fid is None else int(fid), now),
            }
        if cmd == "door":  # a request for a TMCL or LIN front door: its own commands
            return self._door(str(req["door"]), str(req["command"]), list(req.get("args", [])))
        if cmd == "wire":  # shorthand: a wire fault on the next N replies
            return self._inject(
                {"kind": req["kind"], "count": req.get("count", 1), "value": req.get("value")}
            )
        slave = int(req["slave"])
        if not 0 <= slave < len(seg.escs):
            raise IndexError(f"no slave {slave}")
        if cmd == "fault":  # shorthand: a drive fault held until cleared
            kind = str(req["kind"])
            if req.get("active", True):
                return self._inject({"kind": kind, "slave": slave})
            self.faults.clear(None, now, kind)
            drive = getattr(seg.firmware[slave], "device", None)
            if isinstance(drive, Drive):
                drive.inject(kind, False)
            return {"ok": True}
        if cmd in ("al_refuse", "al_fall"):  # shorthands for one-shot AL faults
            return self._inject({"kind": cmd, "slave": slave, "code": req["code"]})
        if cmd == "mbx_drop":  # shorthand: no reply to the next N mailbox requests
            return self._inject({"kind": cmd, "slave": slave, "count": req.get("count", 1)})
        if cmd == "link":  # a cable fault: port 1 of this slave and port 0 of the next
            self.faults.set_cable(slave, int(req.get("port", 1)), bool(req.get("up", False)))
            return {"ok": True}
        if cmd == "peek":
            addr, n = int(req["addr"]), int(req["len"])
            esc = seg.escs[slave]
            return {"ok": True, "data": esc.peek(addr, max(0, min(n, 0x10000 - addr))).hex()}
        if cmd == "poke":
            addr = int(req["addr"])
            data = bytes.fromhex(str(req["data"]))
            esc = seg.escs[slave]
            esc.mem[addr : addr + len(data)] = data
            return {"ok": True}
        if cmd == "od":
            od = getattr(seg.firmware[slave], "od", None)
            if od is None:
                raise ValueError(f"slave {slave} has no object dictionary")
            index, sub = int(req["index"]), int(req.get("sub", 0))
            if od.refresh is not None:
                od.refresh()
            if "value" in req:
                od.set(index, sub, req["value"])
            v = od.value(index, sub)
            return {"ok": True, "value": v if not isinstance(v, bytes) else v.hex()}
        raise ValueError(f"unknown command {cmd!r}")

    def close(self) -> None:
        self.sock.close()
        try:
            self.path.unlink()
        except OSError:
            pass


def _remove_stale(path: Path) -> None:
    """Remove a socket left by a daemon that is gone; refuse one a live daemon serves."""
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        probe.connect(str(path))
    except OSError:
        path.unlink(missing_ok=True)
        return
    finally:
        probe.close()
    raise UserError(f"--ctl {path}: another daemon serves this control socket; pass --ctl PATH")


def request(path: Path, req: dict[str, Any], timeout: float = 2.0) -> dict[str, Any]:
    """The client side: one request, one reply."""
    client = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-ctl-")) / "c.sock"
    try:
        client.bind(str(tmp))
        client.settimeout(timeout)
        client.sendto(json.dumps(req).encode(), str(path))
        data = client.recv(65536)
    except OSError as exc:
        raise UserError(f"--socket {path}: no daemon answered ({exc.strerror or exc})") from exc
    finally:
        client.close()
        try:
            tmp.unlink()
            tmp.parent.rmdir()
        except OSError:
            pass
    reply: dict[str, Any] = json.loads(data)
    return reply
