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

import structlog

from ecatsim.device.drive import Drive
from ecatsim.doors.host import DoorHost
from ecatsim.errors import UserError
from ecatsim.esc import regs
from ecatsim.ethercat import topology
from ecatsim.ethercat.segment import Segment
from ecatsim.faults.engine import FaultEngine
from ecatsim.faults.spec import parse_fault
from ecatsim.slave.eoe import find_eoe
from ecatsim.slave.od import SdoAbort, abort_text

log = structlog.get_logger("ecatsim.ctl.server")

#: one past the last byte address of the ESC (registers and process RAM)
ADDRESS_END = 0x10000

MAX_REQUEST = 4096


def run_dir() -> Path:
    """Where control sockets live: ``ECATSIM_RUN_DIR`` if set, else /run/ecatsim for root,
    else the user's runtime dir."""
    override = os.environ.get("ECATSIM_RUN_DIR")
    if override:
        return Path(override)
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
        self,
        path: Path,
        segment: Segment | None,
        faults: FaultEngine | None,
        doors: DoorHost | None = None,
    ) -> None:
        """``segment`` and ``faults`` are None for a daemon serving front doors only."""
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
            reply = self.answer(data)
            if addr:
                try:
                    self.sock.sendto(json.dumps(reply).encode(), addr)
                except OSError:
                    pass

    def answer(self, data: bytes) -> dict[str, Any]:
        """One request's answer: every request gets one, whatever goes wrong in it."""
        try:
            req = json.loads(data)
            if not isinstance(req, dict):
                raise ValueError('a request is a JSON object like {"cmd": "status"}')
            return self.handle(req)
        except SdoAbort as exc:
            return {"ok": False, "error": abort_text(exc.code), "abort": exc.code}
        except KeyError as exc:
            return {"ok": False, "error": f"missing field {exc}"}
        except (ValueError, TypeError, IndexError, UserError) as exc:
            return {"ok": False, "error": str(exc)}
        except Exception as exc:  # a bug: answer it, log it, keep serving
            log.error("ctl_request_failed", request=data[:200], exc_info=exc)
            return {"ok": False, "error": f"internal error: {exc!r}"}

    def _inject(self, fault: dict[str, Any]) -> dict[str, Any]:
        assert self.faults is not None and self.segment is not None  # handle() checked
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
        doors = self.doors.status() if self.doors is not None else {}
        if self.segment is None or self.faults is None:  # a daemon serving front doors only
            return {"ok": True, "slaves": [], "faults": [], "frames": 0, "bad_frames": 0,
                    "doors": doors}  # fmt: skip
        out = []
        for esc in self.segment.escs:
            m = esc.mem
            eoe = find_eoe(getattr(self.segment.firmware[esc.position], "mbx", None))
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
                    "lost_link": list(m[0x0310 : 0x0310 + (4 if esc.ports & 0xC else 2)]),
                    "ports": esc.ports,
                    "wd_pd_status": m[regs.WD_STATUS_PD] & 1,
                    "wd_expired": m[0x0442],
                    **({"eoe": eoe.status()} if eoe is not None else {}),
                }
            )
        seg = self.segment
        return {
            "ok": True,
            "slaves": out,
            "frames": seg.frames,
            "bad_frames": seg.bad_frames,
            "topology": topology.describe(seg.wiring, [str(e.position) for e in seg.escs]),
            "faults": self.faults.status(),
            "faults_fired": self.faults.fired_total,
            "doors": doors,
        }

    def handle(self, req: dict[str, Any]) -> dict[str, Any]:
        """One request -> one reply."""
        cmd = req["cmd"]
        if cmd == "status":
            return self.status()
        if cmd == "door":  # a request for a TMCL or LIN front door: its own commands
            return self._door(str(req["door"]), str(req["command"]), list(req.get("args", [])))
        seg, faults = self.segment, self.faults
        if seg is None or faults is None:
            raise ValueError(f"{cmd!r}: this daemon serves front doors only (use: status, door)")
        now = seg.clock.now_ns()
        if cmd == "inject":  # any fault, as in the segment YAML's faults: list
            return self._inject(dict(req["fault"]))
        if cmd == "clear":  # one fault by id, or all
            fid = req.get("id")
            return {
                "ok": True,
                "cleared": faults.clear(None if fid is None else int(fid), now),
            }
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
            faults.clear(None, now, kind)
            drive = getattr(seg.firmware[slave], "device", None)
            if isinstance(drive, Drive):
                drive.inject(kind, False)
            return {"ok": True}
        if cmd in ("al_refuse", "al_fall"):  # shorthands for one-shot AL faults
            return self._inject({"kind": cmd, "slave": slave, "code": req["code"]})
        if cmd == "mbx_drop":  # shorthand: no reply to the next N mailbox requests
            return self._inject({"kind": cmd, "slave": slave, "count": req.get("count", 1)})
        if cmd == "link":  # a cable fault: port 1 of this slave and port 0 of the next
            faults.set_cable(slave, int(req.get("port", 1)), bool(req.get("up", False)))
            return {"ok": True}
        if cmd == "peek":
            addr, n = int(req["addr"]), int(req["len"])
            _check_range(addr, n)
            esc = seg.escs[slave]
            return {"ok": True, "data": esc.peek(addr, n).hex()}
        if cmd == "poke":
            addr = int(req["addr"])
            data = bytes.fromhex(str(req["data"]))
            _check_range(addr, len(data))
            esc = seg.escs[slave]
            esc.mem[addr : addr + len(data)] = data
            return {"ok": True}
        if cmd == "mfcio":  # the TMC8460 MFCIO block: status, pins, MFC CTRL SPI access
            mfcio = getattr(seg.firmware[slave], "ctl", None)
            if mfcio is None:
                raise ValueError(f"slave {slave} has no MFCIO block (device: tmc8460)")
            args = [str(a) for a in req.get("args", [])]
            return {"ok": True, **mfcio(str(req.get("op", "status")), args, now)}
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
        if cmd == "pd":  # process data by entry: every mapped entry, one, or set an input
            from ecatsim.slave.pd import request as pd_request

            return pd_request(getattr(seg.firmware[slave], "app", None), req)
        raise ValueError(f"unknown command {cmd!r}")

    def close(self) -> None:
        self.sock.close()
        try:
            self.path.unlink()
        except OSError:
            pass


def _check_range(addr: int, n: int) -> None:
    """A peek or poke stays inside the ESC's 64 KiB address space (TMC8460 §4)."""
    if n < 1:
        raise ValueError(f"length {n}: expected at least 1 byte")
    if not 0 <= addr <= ADDRESS_END - 1 or addr + n > ADDRESS_END:
        raise ValueError(
            f"0x{addr:04X}+{n} runs past the end of the ESC address space "
            f"(0x0000..0x{ADDRESS_END - 1:04X})"
        )


def _alive(path: Path) -> bool:
    """A daemon serves the socket at ``path`` (connecting to a dead one's file fails)."""
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        probe.connect(str(path))
    except OSError:
        return False
    finally:
        probe.close()
    return True


def find_socket(directory: Path | None = None, door: str | None = None) -> Path:
    """The control socket of the one daemon running, when neither --socket nor --link says;
    for a request to front door ``door``: of the one daemon that serves that door.

    With none or several, one line says which exist and what to pass."""
    directory = directory or run_dir()
    live = sorted(p for p in directory.glob("*.sock") if _alive(p))
    if len(live) == 1:
        return live[0]
    if door is not None and len(live) > 1:
        serving = [p for p in live if door in _doors_of(p)]
        if len(serving) == 1:
            return serving[0]
        if not serving:
            names = ", ".join(p.name.removesuffix(".sock") for p in live)
            raise UserError(f"ctl: none of the running daemons ({names}) serves the door {door}")
        live = serving
    if not live:
        raise UserError(
            f"ctl: no running daemon has a control socket in {directory}; start one with "
            "'ecatsim run', or give --socket PATH (its --ctl)"
        )
    names = ", ".join(p.name.removesuffix(".sock") for p in live)
    raise UserError(f"ctl: several daemons are running ({names}); say which with --link NAME")


def _doors_of(path: Path) -> dict[str, Any]:
    """The front doors the daemon at ``path`` serves (none if it does not answer)."""
    try:
        doors = request(path, {"cmd": "status"}, timeout=1.0).get("doors")
    except (UserError, ValueError):
        return {}
    return doors if isinstance(doors, dict) else {}


def _remove_stale(path: Path) -> None:
    """Remove a socket left by a daemon that is gone; refuse one a live daemon serves."""
    if not _alive(path):
        path.unlink(missing_ok=True)
        return
    raise UserError(
        f"{path}: a running daemon answers on this control socket (see it with 'ecatsim ctl "
        f"--socket {path} status'); stop it first, or give this daemon another socket with "
        "--ctl PATH if it serves something else"
    )


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
