"""The daemon's own reply time, from kernel timestamps on both ends of the link.

Two packet sockets stamp each EtherCAT frame (SO_TIMESTAMPNS) as the kernel receives it: the
master's request arriving at the daemon's interface, and the daemon's reply arriving at the
master's interface. The difference is the time the daemon took to answer, as a tap on the
wire would see it: the master's own scheduling (when it sends, when it reads) is not in it.
(The sending side cannot be stamped: the daemon and KickCAT send with
PACKET_QDISC_BYPASS, which packet taps do not see.) Request and reply are paired by the
index byte of the first datagram (ETG.1000.4 §5.4.1.2), which the slaves leave unchanged.
    with ReplyTimer((pair.master_ns, pair.master_if), (pair.slave_ns, pair.slave_if)) as rt:
        ...  # run the master
    print(rt.stats())
"""

from __future__ import annotations

import math
import select
import socket
import struct
import threading
from types import TracebackType
from typing import Any

ETH_P_ECAT = 0x88A4
PACKET_OUTGOING = 4
SO_TIMESTAMPNS = 35
#: Ethernet header + EtherCAT header, then the first datagram's cmd and idx
IDX_OFFSET = 14 + 2 + 1

End = tuple[str | None, str]  # (network namespace or None, interface)


def percentile(sorted_us: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of sorted values by nearest rank: the smallest value with
    at least ``q`` of the values at or below it."""
    if not sorted_us:
        return float("nan")
    k = min(len(sorted_us), max(1, math.ceil(q * len(sorted_us))))
    return sorted_us[k - 1]


def _open(end: End) -> socket.socket:
    def make() -> socket.socket:
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
        s.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        s.bind((end[1], ETH_P_ECAT))
        return s

    if end[0] is None:
        return make()
    from tests.integration.netns import in_netns

    with in_netns(end[0]):
        return make()


class ReplyTimer:
    """Requests stamped at the daemon's end, replies at the master's; paired afterwards."""

    def __init__(self, master: End, daemon: End) -> None:
        self._ends = (master, daemon)
        #: (stamp ns, is_reply, idx) in the order read
        self.events: list[tuple[int, bool, int]] = []
        self._stop = threading.Event()
        self._socks: list[socket.socket] = []
        self._thread: threading.Thread | None = None

    def __enter__(self) -> ReplyTimer:
        self._socks = [_open(self._ends[0]), _open(self._ends[1])]
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(
        self, et: type[BaseException] | None, e: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2)
        for s in self._socks:
            s.close()

    def _run(self) -> None:
        master = self._socks[0]
        while not self._stop.is_set():
            for s in select.select(self._socks, [], [], 0.05)[0]:
                data, anc, _flags, addr = s.recvmsg(64, socket.CMSG_SPACE(16))
                if addr[2] == PACKET_OUTGOING or len(data) <= IDX_OFFSET:
                    continue
                for lvl, typ, d in anc:
                    if lvl == socket.SOL_SOCKET and typ == SO_TIMESTAMPNS:
                        sec, nsec = struct.unpack("qq", d[:16])
                        self.events.append(
                            (sec * 1_000_000_000 + nsec, s is master, data[IDX_OFFSET])
                        )

    def reply_us(self) -> tuple[list[float], int]:
        """Reply times in microseconds, and how many requests got no reply (or replies no
        request)."""
        pending: dict[int, int] = {}
        out: list[float] = []
        unpaired = 0
        for t, is_reply, idx in sorted(self.events):
            if not is_reply:
                unpaired += idx in pending
                pending[idx] = t
            elif (t0 := pending.pop(idx, None)) is not None:
                out.append((t - t0) / 1000)
            else:
                unpaired += 1
        return out, unpaired + len(pending)

    def stats(self) -> dict[str, Any]:
        times, unpaired = self.reply_us()
        us = sorted(times)
        out: dict[str, Any] = {"frames": len(us), "unpaired": unpaired}
        for name, q in (("median", 0.5), ("p99", 0.99), ("p99.99", 0.9999)):
            out[name] = round(percentile(us, q), 1)
        out["max"] = round(us[-1], 1) if us else float("nan")
        return out
