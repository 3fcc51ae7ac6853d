"""Every reply timed from kernel timestamps: packet taps on the link's ends.

A :class:`Capture` holds packet sockets on one or both ends of the link, each in its
network namespace, that stamp every EtherCAT frame with the kernel's time as it is seen
(SO_TIMESTAMPNS); a thread reads them. A frame's direction is where it was seen: on the
master's end a frame the host sends is a request and one it receives a reply; with taps
on both ends what arrives at the daemon is a request and what arrives at the master a
reply (not bit 1 of the source MAC, which a master may set in its own requests: KickCAT
does). Request and reply are paired by the index byte of the first datagram
(ETG.1000.4 §5.4.1.2), which the slaves leave unchanged. Two uses:

- :meth:`Capture.master_end` (``ecatsim bench --bringup``): one tap of every protocol on
  the master's interface sees the master's requests on their way out and the replies on
  their way in: the reply time as the master sees it. :func:`analyse` reports it.
- :meth:`Capture.both_ends` (the round-trip bench, the KickCAT tests): the master's
  requests as they arrive at the daemon's interface, the replies as they arrive at the
  master's: the daemon's own reply time, the master's scheduling not in it. (The sending
  side cannot be stamped there: the daemon and KickCAT send with PACKET_QDISC_BYPASS,
  which packet taps do not see; taps of the EtherCAT protocol only, so the C floor's
  replies are not copied to them.) :func:`reply_stats` reports it.

A request seen again with the same index and the same datagrams while its first copy is
unanswered is a resend (SOEM resends after its 2 ms timeout; within ``RESEND_WINDOW_NS``).
:func:`analyse` and :func:`reply_stats` are plain data in, plain data out.

    with Capture.master_end(pair.master_ns, pair.master_if) as cap:
        cap.mark("config_init")
        ...  # run the master
    print(analyse(cap.frames(), cap.marks))
"""

from __future__ import annotations

import math
import select
import socket
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from ecatsim.bench.netns import in_netns

ETH_P_ECAT = 0x88A4
#: every protocol: a tap of one protocol does not see the frames the host sends. Ref: packet(7)
ETH_P_ALL = 0x0003
PACKET_OUTGOING = 4
SO_TIMESTAMPNS = 35
#: SO_RCVBUF beyond net.core.rmem_max (root): the thread may fall behind, the kernel
#: keeps the frames. Ref: socket(7)
SO_RCVBUFFORCE = 33
RCVBUF = 64 << 20
#: a request sent again with the same index and datagram this soon is a resend; later it
#: is a new request (a master's cyclic frames repeat while their outputs do not change)
RESEND_WINDOW_NS = 20_000_000
#: bytes of each frame kept: Ethernet + EtherCAT header + the first datagram's header and
#: up to 48 bytes of its data (enough to tell a resend from a new request)
SNAP = 14 + 2 + 10 + 48
#: the longest frame read whole (``keep_wkc``): Ethernet with an 802.1Q tag, no FCS
FRAME_MAX = 1518
#: logical addressing: LRD, LWR, LRW (ETG.1000.4 Table 11)
LOGICAL = (10, 11, 12)
#: ETG.1000.4 Table 11
CMD_NAMES = ("NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD", "BWR", "BRW",
             "LRD", "LWR", "LRW", "ARMW", "FRMW")  # fmt: skip
_HDR = struct.Struct("<BBHHH")
_STAMP = struct.Struct("qq")

End = tuple[str | None, str]  # (network namespace or None, interface)


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
    #: the first datagram's working counter (-1: the capture did not keep it)
    wkc: int = -1


def _first_datagram(data: bytes) -> int:
    """Where the first datagram of an EtherCAT frame starts (an 802.1Q tag is stepped
    over), -1 if ``data`` is not EtherCAT with a datagram header."""
    off = 12
    if len(data) >= off + 2 and data[off : off + 2] == b"\x81\x00":
        off += 4
    if len(data) < off + 2 + 2 + 10 or data[off : off + 2] != b"\x88\xa4":
        return -1
    return off + 2 + 2


def first_wkc(data: bytes) -> int:
    """The working counter of a frame's first datagram, -1 if ``data`` does not hold it
    (not EtherCAT, or cut short). Ref: ETG.1000.4 §5.4.1.2 (the WKC follows the data)."""
    p = _first_datagram(data)
    if p < 0:
        return -1
    end = p + 10 + (_HDR.unpack_from(data, p)[4] & 0x7FF)
    return int.from_bytes(data[end : end + 2], "little") if len(data) >= end + 2 else -1


def parse(data: bytes, t_ns: int, reply: bool | None = None, wkc: int | None = None
          ) -> Frame | None:  # fmt: skip
    """A captured frame as a :class:`Frame`, None if it is not EtherCAT with a datagram
    (an 802.1Q tag is stepped over). A reply if ``reply`` says so, or without it if bit 1
    of the source MAC is set (the slaves set it, ETG.1000.4 §5.2). Its first datagram's
    WKC is ``wkc`` if given (the capture read it before it cut the frame short), else
    :func:`first_wkc` of ``data``."""
    p = _first_datagram(data)
    if p < 0:
        return None
    cmd, idx, adp, ado, lf = _HDR.unpack_from(data, p)
    if reply is None:
        reply = bool(data[6] & 0x02)
    return Frame(t_ns, reply, idx, cmd, adp, ado, lf & 0x7FF,
                 bytes(data[p : p + 10 + min(lf & 0x7FF, 48)]),
                 first_wkc(data) if wkc is None else wkc)  # fmt: skip


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0..1) of sorted values by nearest rank: the smallest value with
    at least ``q`` of the values at or below it."""
    if not values:
        return float("nan")
    k = min(len(values), max(1, math.ceil(q * len(values))))
    return values[k - 1]


@dataclass(frozen=True, slots=True)
class Pairing:
    """Requests paired with their replies: (reply time in us, request) of each answered
    request, resends (the same index and datagram again while unanswered; the wait runs
    from the first copy), requests never answered, replies with no request waiting, and
    the first resends with where they went and after how long."""

    times: list[tuple[float, Frame]]
    resends: int
    unanswered: int
    extra_replies: int
    resent: list[dict[str, Any]]


def pair(frames: Sequence[Frame], keep_resent: int = 10) -> Pairing:
    """Each request (from its first copy on the wire) paired with its first reply."""
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
                    if len(resent) < keep_resent:
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
    return Pairing(times, resends, unanswered + len(pending), extra, resent)


def late_replies(frames: Sequence[Frame], over_us: float) -> list[tuple[int, int]]:
    """Each request answered ``over_us`` or more after it: (request, reply) kernel times
    (CLOCK_REALTIME ns). Requests never answered are not in it (``unanswered``)."""
    return [(req.t_ns, req.t_ns + round(us * 1e3)) for us, req in pair(frames, 0).times
            if us >= over_us]  # fmt: skip


def analyse(
    frames: Sequence[Frame], marks: Sequence[tuple[int, str]] = (), slowest: int = 10
) -> dict[str, Any]:
    """Reply times of every request in microseconds: p50, p99.9, max, how many over 1 ms
    and over 2 ms, resends, requests never answered, replies with no request waiting, and
    the ``slowest`` requests with their command and address. With ``marks`` ((time ns,
    name) in time order, each the start of a phase), the same figures per phase too (a
    request belongs to the phase it was sent in)."""
    p = pair(frames, slowest)
    out = _figures(p.times, slowest)
    out.update(resends=p.resends, unanswered=p.unanswered, extra_replies=p.extra_replies,
               resent=p.resent)  # fmt: skip
    if marks:
        starts = sorted(marks)
        phases: dict[str, list[tuple[float, Frame]]] = {name: [] for _, name in starts}
        for us, req in p.times:
            name = starts[0][1]
            for t, n in starts:
                if req.t_ns >= t:
                    name = n
            phases[name].append((us, req))
        out["phases"] = {name: _figures(v, 3) for name, v in phases.items()}
    return out


def reply_stats(frames: Sequence[Frame]) -> dict[str, Any]:
    """The daemon's reply times in microseconds (median, p99, p99.99, max), how many were
    paired, and how many requests or replies were not (``unpaired``: resent, unanswered,
    or a reply with no request)."""
    p = pair(frames, 0)
    us = sorted(t for t, _ in p.times)
    out: dict[str, Any] = {"frames": len(us),
                           "unpaired": p.resends + p.unanswered + p.extra_replies}  # fmt: skip
    for name, q in (("median", 0.5), ("p99", 0.99), ("p99.99", 0.9999)):
        out[name] = round(percentile(us, q), 1)
    out["max"] = round(us[-1], 1) if us else float("nan")
    return out


def process_cycles(frames: Sequence[Frame], start_ns: int, end_ns: int, expected: int,
                   timeout_ns: int, keep: int = 20) -> dict[str, Any]:  # fmt: skip
    """The process-data cycles a master sent between ``start_ns`` and ``end_ns`` as the
    wire shows them, whatever the master: its logical requests (LRD, LWR, LRW) in time
    order, a cycle starting at each request to the lowest logical address among them (a
    master splits its process image over frames by address); each reply is paired with
    the request of its index. A reply later than ``timeout_ns`` after its request comes
    after the master stopped waiting for it: that frame is lost as well as one never
    answered. A cycle's WKC is the sum of its frames' first-datagram WKCs, as SOEM sums
    them (a lost frame adds nothing). Returns how many cycles and frames, the frames lost
    (``lost``; ``late`` of them answered too late), the cycles whose WKC is not
    ``expected`` (``wkc_errors``) and the first ``keep`` of those WKCs. The frames need
    their WKC (a capture with ``keep_wkc``). Ref: ETG.1000.4 §5.4.1.2, Table 11."""
    window = sorted((f for f in frames if start_ns <= f.t_ns), key=lambda f: f.t_ns)
    logical = [f for f in window if not f.reply and f.cmd in LOGICAL and f.t_ns < end_ns]
    low = min((f.adp | f.ado << 16 for f in logical), default=0)
    sums: list[int] = []
    pending: dict[int, tuple[int, int]] = {}  # index -> (cycle, time) of a request waiting
    lost = late = 0
    for f in window:
        if not f.reply:
            if f.t_ns >= end_ns:
                continue
            if pending.pop(f.idx, None) is not None:
                lost += 1  # the index again: the request before had no reply
            if f.cmd in LOGICAL:
                if (f.adp | f.ado << 16) == low:
                    sums.append(0)
                if sums:
                    pending[f.idx] = (len(sums) - 1, f.t_ns)
        else:
            waiting = pending.pop(f.idx, None)
            if waiting is not None:
                if f.wkc < 0:
                    raise ValueError("the capture kept no WKC: Capture(keep_wkc=True)")
                if f.t_ns - waiting[1] > timeout_ns:
                    late += 1
                else:
                    sums[waiting[0]] += f.wkc
    lost += len(pending) + late
    short = [w for w in sums if w != expected]
    return {"cycles": len(sums), "frames": len(logical), "lost": lost, "late": late,
            "wkc_errors": len(short), "expected_wkc": expected,
            "wkc_error_seen": short[:keep]}  # fmt: skip


def cycle_frames(frames: Sequence[Frame], start_ns: int, end_ns: int, least: float = 0.5
                 ) -> list[dict[str, Any]]:  # fmt: skip
    """The reply times of a cycle's frames, each by its place in the cycle: the logical
    requests sent between ``start_ns`` and ``end_ns`` grouped by their logical address (a
    master splits its process image over frames by address, the same each cycle), in
    address order; a group with fewer than ``least`` of the largest group's requests (a
    stray frame) is left out. Each: command and logical address of its first request,
    frames, p50, p99.9 and max (us). Where a cycle's frames wait behind each other or
    behind the SYNC0 work, the later ones show it (decision P98)."""
    groups: dict[int, list[tuple[float, Frame]]] = {}
    for us, r in pair(frames, 0).times:
        if r.cmd in LOGICAL and start_ns <= r.t_ns < end_ns:
            groups.setdefault(r.adp | r.ado << 16, []).append((us, r))
    most = max((len(v) for v in groups.values()), default=0)
    out = []
    for lad in sorted(groups):
        times = groups[lad]
        if len(times) < least * most:
            continue
        f = _figures(times, 0)
        out.append(
            {"cmd": _name(times[0][1].cmd), "logical": f"0x{lad:08X}"}
            | {k: f[k] for k in ("frames", "p50_us", "p999_us", "max_us")}
        )
    return out


def _name(cmd: int) -> str:
    return CMD_NAMES[cmd] if cmd < len(CMD_NAMES) else f"0x{cmd:02X}"


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


class Capture:
    """Packet sockets on ``ends`` stamping EtherCAT frames, read by a thread; with
    ``outgoing`` a tap of every protocol that keeps the frames the host sends too, else a
    tap of EtherCAT that keeps the frames arriving; of each frame its first ``snap``
    bytes, and with ``keep_wkc`` its first datagram's WKC read from the whole frame
    (:attr:`wkcs`). ``mark(name)`` starts a phase now."""

    def __init__(self, ends: Sequence[End], outgoing: bool, snap: int = SNAP,
                 keep_wkc: bool = False) -> None:  # fmt: skip
        self._ends = tuple(ends)
        self._outgoing = outgoing
        self._snap = snap
        self._keep_wkc = keep_wkc
        #: (kernel time ns, a reply or not, the frame's first ``snap`` bytes) as read
        self.raw: list[tuple[int, bool, bytes]] = []
        #: with ``keep_wkc``: the first datagram's WKC of each frame of :attr:`raw`
        self.wkcs: list[int] = []
        self.marks: list[tuple[int, str]] = []
        self._stop = threading.Event()
        self._socks: list[socket.socket] = []
        self._thread: threading.Thread | None = None

    @classmethod
    def master_end(cls, netns: str | None, iface: str, snap: int = SNAP,
                   keep_wkc: bool = False) -> Capture:  # fmt: skip
        """The master's requests going out and the replies coming in, on its interface."""
        return cls(((netns, iface),), outgoing=True, snap=snap, keep_wkc=keep_wkc)

    @classmethod
    def both_ends(cls, master: End, daemon: End) -> Capture:
        """The requests arriving at the daemon, the replies arriving at the master."""
        return cls((master, daemon), outgoing=False)

    def frames(self) -> list[Frame]:
        """The EtherCAT frames captured so far."""
        if self._keep_wkc:  # the thread may be one WKC ahead: zip stops at the shorter
            pairs = zip(self.raw, self.wkcs, strict=False)
            kept = (parse(data, t, reply, w) for (t, reply, data), w in pairs)
            return [f for f in kept if f is not None]
        out = (parse(data, t, reply) for t, reply, data in self.raw)
        return [f for f in out if f is not None]

    def stats(self) -> dict[str, Any]:
        """:func:`reply_stats` of the frames captured so far."""
        return reply_stats(self.frames())

    def _open(self, end: End) -> socket.socket:
        def make() -> socket.socket:
            proto = ETH_P_ALL if self._outgoing else ETH_P_ECAT
            s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(proto))
            s.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            try:
                s.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, RCVBUF)
            except PermissionError:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
            s.bind((end[1], proto))
            return s

        if end[0] is None:
            return make()
        with in_netns(end[0]):
            return make()

    def __enter__(self) -> Capture:
        self._socks = [self._open(end) for end in self._ends]
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        for s in self._socks:
            s.close()

    def mark(self, name: str) -> None:
        """A phase starts now (the capture's clock: CLOCK_REALTIME, as SO_TIMESTAMPNS)."""
        self.marks.append((time.time_ns(), name))

    def _run(self) -> None:
        space = socket.CMSG_SPACE(_STAMP.size)
        keep_outgoing, snap, keep_wkc = self._outgoing, self._snap, self._keep_wkc
        size = FRAME_MAX if keep_wkc else snap
        master = self._socks[0]  # the master's end comes first
        raw, wkcs = self.raw, self.wkcs
        while not self._stop.is_set():  # a busy link keeps select from ever timing out
            ready = select.select(self._socks, [], [], 0.05)[0]
            for s in ready:
                data, anc, _flags, addr = s.recvmsg(size, space)
                sent = addr[2] == PACKET_OUTGOING
                if sent and not keep_outgoing:
                    continue
                # one end: what the master sends is a request; two: what reaches the master
                reply = not sent if keep_outgoing else s is master
                for lvl, typ, d in anc:
                    if lvl == socket.SOL_SOCKET and typ == SO_TIMESTAMPNS:
                        sec, nsec = _STAMP.unpack_from(d)
                        if keep_wkc:
                            wkcs.append(first_wkc(data))
                            data = data[:snap]
                        raw.append((sec * 1_000_000_000 + nsec, reply, data))
