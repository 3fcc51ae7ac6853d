"""Local control socket: status, drive faults, ESC memory peek/poke, OD read/write.

A unix datagram socket (mode 0600) carrying one JSON request and one JSON reply per
datagram. It is served by the daemon loop between frames, never inside frame processing.
"""

from __future__ import annotations

import json
import os
import socket
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ecatsim.device.drive import Drive
from ecatsim.errors import UserError
from ecatsim.segment import Segment
from ecatsim.slave.al import AlState
from ecatsim.wirefault import KINDS, WireFault

MAX_REQUEST = 4096


class ControlSocket:
    """The daemon side."""

    def __init__(self, path: Path, segment: Segment) -> None:
        self.path = path
        self.segment = segment
        #: set by the daemon: arms a wire fault on its replies
        self.arm_wire: Callable[[WireFault], None] | None = None
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists():
            path.unlink()
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

    def _drive(self, slave: int) -> Drive:
        fw = self.segment.firmware[slave]
        device = getattr(fw, "device", None)
        if not isinstance(device, Drive):
            raise ValueError(f"slave {slave} has no drive")
        return device

    def handle(self, req: dict[str, Any]) -> dict[str, Any]:
        """One request -> one reply."""
        cmd = req["cmd"]
        seg = self.segment
        if cmd == "status":
            out = []
            for esc in seg.escs:
                m = esc.mem
                al = struct.unpack_from("<HxxH", m, 0x0130)
                out.append(
                    {
                        "position": esc.position,
                        "station": struct.unpack_from("<H", m, 0x0010)[0],
                        "al_status": al[0],
                        "al_status_code": al[1],
                        "dl_status": struct.unpack_from("<H", m, 0x0110)[0],
                        "pu_errors": m[0x030C],
                        "wd_expired": m[0x0442],
                    }
                )
            return {"ok": True, "slaves": out, "frames": seg.frames, "bad_frames": seg.bad_frames}
        if cmd == "wire":
            kind = str(req["kind"])
            if kind not in KINDS or self.arm_wire is None:
                raise ValueError(f"wire fault {kind!r}: use one of {', '.join(KINDS)}")
            self.arm_wire(WireFault(kind, int(req.get("count", 1)), int(req.get("value", 1))))
            return {"ok": True}
        slave = int(req["slave"])
        if not 0 <= slave < len(seg.escs):
            raise IndexError(f"no slave {slave}")
        if cmd == "fault":
            self._drive(slave).inject(str(req["kind"]), bool(req.get("active", True)))
            return {"ok": True}
        fw = seg.firmware[slave]
        if cmd == "al_refuse":  # refuse the next state change with an AL status code
            fw.refuse_next = int(req["code"])  # type: ignore[attr-defined]
            return {"ok": True}
        if cmd == "al_fall":  # fall from OP to SAFEOP + error with a code
            fw.fail(AlState.SAFEOP, int(req["code"]), seg.clock.now_ns())  # type: ignore[attr-defined]
            return {"ok": True}
        if cmd == "mbx_drop":  # no reply to the next N mailbox requests
            mbx = getattr(fw, "mbx", None)
            if mbx is None:
                raise ValueError(f"slave {slave} has no mailbox")
            mbx.drop_next = int(req.get("count", 1))
            return {"ok": True}
        if cmd == "link":  # a cable fault: port 1 of this slave and port 0 of the next
            port, up = int(req.get("port", 1)), bool(req.get("up", False))
            seg.escs[slave].set_link(port, up)
            peer = slave + 1 if port == 1 else slave - 1
            if 0 <= peer < len(seg.escs):
                seg.escs[peer].set_link(1 - port, up)
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
