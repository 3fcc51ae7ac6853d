"""Every reply timed as the master's end of the link sees it.

One packet socket on the master's interface, in the master's network namespace, stamps
every EtherCAT frame with the kernel's time (SO_TIMESTAMPNS): the master's requests on
their way out and the replies on their way in. A frame is a reply when bit 1 of its source
MAC is set (the slaves set it, ETG.1000.4 §5.2; the daemon's ``mark_processed``); request
and reply are paired by the index byte of the first datagram (ETG.1000.4 §5.4.1.2),
which the slaves leave unchanged. A request seen again with the same index and the same
datagrams while its first copy is unanswered is a resend (SOEM resends after its 2 ms
timeout; within ``RESEND_WINDOW_NS``). ``analyse`` turns the stamped frames into the
figures ``ecatsim bench --bringup`` reports; it is plain data in, plain data out
(tests/unit/test_capture.py).

    with MasterCapture(pair.master_ns, pair.master_if) as cap:
        cap.mark("config_init")
        ...  # run the master
    print(analyse(cap.frames, cap.marks))
"""

from __future__ import annotations

import math
import select
import socket
import struct
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

ETH_P_ECAT = 0x88A4
#: every protocol: a tap of one protocol does not see the frames the host sends, and
#: ``parse`` keeps the EtherCAT ones. Ref: packet(7)
ETH_P_ALL = 0x0003
SO_TIMESTAMPNS = 35
#: SO_RCVBUF beyond net.core.rmem_max (root): the thread may fall behind, the kernel
#: keeps the frames. Ref: socket(7)
SO_RCVBUFFORCE = 33
#: a request sent again with the same index and datagram this soon is a resend; later it
#: is a new request (a master's cyclic frames repeat while their outputs do not change)
RESEND_WINDOW_NS = 20_000_000
#: bytes of each frame kept: Ethernet + EtherCAT header + the first datagram's header and
#: up to 48 bytes of its data (enough to tell a resend from a new request)
SNAP = 14 + 2 + 10 + 48
#: Ethernet header then the EtherCAT header: the first datagram starts here
DG = 14 + 2
#: ETG.1000.4 Table 11
CMD_NAMES = ("NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD", "BWR", "BRW",
             "LRD", "LWR", "LRW", "ARMW", "FRMW")  # fmt: skip
_HDR = struct.Struct("<BBHHH")


@dataclass(frozen=True, slots=True)
class Frame:
    """One stamped frame: kernel time (ns), a reply or not, and its first datagram."""

    t_ns: int
    reply: bool
    idx: int
    cmd: int
    adp: int
    ado: int
    length: int
    #: the datagram bytes kept (without the reply's changes for a request)
    body: bytes


def parse(data: bytes, t_ns: int) -> Frame | None:
    """A captured frame as a :class:`Frame`, None if it is not EtherCAT with a datagram
    (an 802.1Q tag is stepped over)."""
    off = 12
    if len(data) >= off + 2 and data[off : off + 2] == b"\x81\x00":
        off += 4
    if len(data) < off + 2 + 2 + 10 or data[off : off + 2] != b"\x88\xa4":
        return None
    p = off + 2 + 2
    cmd, idx, adp, ado, lf = _HDR.unpack_from(data, p)
    return Frame(t_ns, bool(data[6] & 0x02), idx, cmd, adp, ado, lf & 0x7FF,
                 bytes(data[p : p + 10 + min(lf & 0x7FF, 48)]))  # fmt: skip


def percentile(values: list[float], q: float) -> float:
    """Nearest rank: the smallest value with at least ``q`` of the values at or below it."""
    if not values:
        return float("nan")
    k = min(len(values), max(1, math.ceil(q * len(values))))
    return values[k - 1]


def _name(cmd: int) -> str:
    return CMD_NAMES[cmd] if cmd < len(CMD_NAMES) else f"0x{cmd:02X}"


def analyse(
    frames: list[Frame], marks: Sequence[tuple[int, str]] = (), slowest: int = 10
) -> dict[str, Any]:
    """Reply times of every request (from its first copy on the wire to its first reply),
    in microseconds: p50, p99.9, max, how many over 1 ms and over 2 ms, resends (the same
    index and datagram sent again while unanswered), requests never answered, replies with
    no request waiting, and the ``slowest`` requests with their command and address. With
    ``marks`` ((time ns, name) in time order, each the start of a phase), the same
    figures per phase too (a request belongs to the phase it was sent in)."""
    pending: dict[int, Frame] = {}
    times: list[tuple[float, Frame]] = []
    resends = unanswered = extra = 0
    resent: list[dict[str, Any]] = []
    for f in sorted(frames, key=lambda f: f.t_ns):
        if not f.reply:
            old = pending.get(f.idx)
            if old is not None:
                if old.body == f.body and f.t_ns - old.t_ns < RESEND_WINDOW_NS:
                    resends += 1
                    if len(resent) < slowest:
                        resent.append(
                            _where(old) | {"after_us": round((f.t_ns - old.t_ns) / 1e3, 1)}
                        )
                    continue  # the wait runs from the first copy
                unanswered += 1  # a new request with the index: the old one had no reply
            pending[f.idx] = f
        else:
            req = pending.pop(f.idx, None)
            if req is None:
                extra += 1  # the second reply to a resent request, or an unknown one
                continue
            times.append(((f.t_ns - req.t_ns) / 1e3, req))
    unanswered += len(pending)
    out = _figures(times, slowest)
    out.update(resends=resends, unanswered=unanswered, extra_replies=extra, resent=resent)
    if marks:
        starts = sorted(marks)
        phases: dict[str, list[tuple[float, Frame]]] = {name: [] for _, name in starts}
        for us, req in times:
            name = starts[0][1]
            for t, n in starts:
                if req.t_ns >= t:
                    name = n
            phases[name].append((us, req))
        out["phases"] = {name: _figures(v, 3) for name, v in phases.items()}
    return out


def _where(req: Frame) -> dict[str, Any]:
    return {"cmd": _name(req.cmd), "adp": f"0x{req.adp:04X}", "ado": f"0x{req.ado:04X}",
            "length": req.length}  # fmt: skip


def _figures(times: list[tuple[float, Frame]], slowest: int) -> dict[str, Any]:
    us = sorted(t for t, _ in times)
    worst = sorted(times, key=lambda x: -x[0])[:slowest]
    return {
        "frames": len(us),
        "p50_us": round(percentile(us, 0.5), 1),
        "p999_us": round(percentile(us, 0.999), 1),
        "max_us": round(us[-1], 1) if us else float("nan"),
        "over_1ms": sum(t > 1000 for t in us),
        "over_2ms": sum(t > 2000 for t in us),
        "slowest": [_where(r) | {"us": round(t, 1)} for t, r in worst],
    }


class MasterCapture:
    """A packet socket on the master's interface stamping every EtherCAT frame, both ways,
    read by a thread into ``frames``; ``mark(name)`` starts a phase at the current time."""

    def __init__(self, netns: str | None, iface: str) -> None:
        self._end = (netns, iface)
        self.frames: list[Frame] = []
        self.marks: list[tuple[int, str]] = []
        self._stop = threading.Event()
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None

    def _open(self) -> socket.socket:
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        s.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        try:
            s.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 64 << 20)
        except PermissionError:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 64 << 20)
        s.bind((self._end[1], ETH_P_ALL))
        return s

    def __enter__(self) -> MasterCapture:
        if self._end[0] is None:
            self._sock = self._open()
        else:
            from tests.integration.netns import in_netns

            with in_netns(self._end[0]):
                self._sock = self._open()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        if self._sock is not None:
            self._sock.close()

    def mark(self, name: str) -> None:
        """A phase starts now (the capture's clock: CLOCK_REALTIME, as SO_TIMESTAMPNS)."""
        import time

        self.marks.append((time.time_ns(), name))

    def _run(self) -> None:
        s = self._sock
        assert s is not None
        space = socket.CMSG_SPACE(16)
        while True:
            if not select.select([s], [], [], 0.05)[0]:
                if self._stop.is_set():
                    return
                continue
            data, anc, _flags, _addr = s.recvmsg(SNAP, space)
            for lvl, typ, d in anc:
                if lvl == socket.SOL_SOCKET and typ == SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack("qq", d[:16])
                    f = parse(data, sec * 1_000_000_000 + nsec)
                    if f is not None:
                        self.frames.append(f)
