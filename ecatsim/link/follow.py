"""Run the daemon on the CPU the master's frames come from (decision K5).

A master polls for its reply right after sending, and many sleep between polls (KickCAT:
``recv`` with ``MSG_DONTWAIT``, then a 20 us nap, until its 2 ms deadline; no last try after
the deadline). On a busy host such a nap can end milliseconds late, and the reply that came
meanwhile is never read. On a veth pair or a local NIC the frame is delivered to the daemon
on the CPU that sent it; a real-time daemon woken on that same CPU preempts the master at
once and the reply is queued before the master's first poll, whatever else runs.

The CPU a frame arrived on comes from a packet fanout group (``PACKET_FANOUT_CPU``: each
frame goes to the member whose index is the receiving CPU, packet(7)): one probe socket per
CPU, each keeping one byte of each EtherCAT frame it gets. Every ``PERIOD_NS`` the daemon
drains the probes and, when most frames came from another CPU than the one it runs on, pins
itself there (``sched_setaffinity``). Only while it runs SCHED_FIFO: an ordinary task
woken on the master's CPU would wait behind it.
"""

from __future__ import annotations

import os
import socket

from ecatsim.link.raw import (
    ETH_P_8021Q,
    ETH_P_ALL,
    ETH_P_ECAT,
    PACKET_OUTGOING,
    SOL_PACKET,
    attach_filter,
)

#: packet(7): PACKET_FANOUT and its CPU mode (linux/if_packet.h)
PACKET_FANOUT = 18
PACKET_FANOUT_CPU = 2
#: how often the probes are read
PERIOD_NS = 10_000_000
#: each probe's receive buffer: room for a few hundred one-byte frames
PROBE_BUF = 1 << 18

#: EtherCAT frames (plain or 802.1Q-tagged) that arrive, not our own replies; one byte kept.
#: Ref: filter(7), ETG.1000.4 §5.2 (EtherType 0x88A4).
PROBE_FILTER: tuple[tuple[int, int, int, int], ...] = (
    (0x20, 0, 0, 0xFFFFF004),  # 0 ld  pkttype (SKF_AD_OFF + SKF_AD_PKTTYPE)
    (0x15, 6, 0, PACKET_OUTGOING),  # 1 jeq PACKET_OUTGOING -> 8 (drop)
    (0x28, 0, 0, 12),  # 2 ldh [12]
    (0x15, 3, 0, ETH_P_ECAT),  # 3 jeq 0x88A4 -> 7 (keep)
    (0x15, 0, 3, ETH_P_8021Q),  # 4 jne 0x8100 -> 8 (drop)
    (0x28, 0, 0, 16),  # 5 ldh [16]
    (0x15, 0, 1, ETH_P_ECAT),  # 6 jne 0x88A4 -> 8 (drop)
    (0x06, 0, 0, 1),  # 7 ret 1
    (0x06, 0, 0, 0),  # 8 ret 0
)


class CpuFollower:
    """Probe sockets on ``iface`` (a fanout group, one member per CPU) and the pinning."""

    def __init__(self, iface: str) -> None:
        self.ncpu = os.cpu_count() or 1
        self.allowed = os.sched_getaffinity(0)
        self.cpu: int | None = None  # where the daemon is pinned by us (None: not yet)
        self.due_ns = 0
        self.moves = 0
        self._buf = bytearray(1)
        self.probes: list[socket.socket] = []
        group = (os.getpid() & 0xFFFF) | (PACKET_FANOUT_CPU << 16)
        try:
            for _ in range(self.ncpu):
                s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
                self.probes.append(s)
                attach_filter(s, PROBE_FILTER)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, PROBE_BUF)
                s.bind((iface, ETH_P_ALL))
                s.setsockopt(SOL_PACKET, PACKET_FANOUT, group)
                s.setblocking(False)
        except OSError:
            self.close()
            raise

    def counts(self) -> list[int]:
        """Frames received on each CPU since the last call (the probes drained)."""
        out = []
        for s in self.probes:
            n = 0
            while True:
                try:
                    s.recv_into(self._buf)
                except (BlockingIOError, InterruptedError):
                    break
                n += 1
            out.append(n)
        return out

    def poll(self, now_ns: int) -> int | None:
        """Every PERIOD_NS: pin the daemon to the CPU most frames came from, if it may run
        there and is not there yet. Returns the CPU it moved to, else None. OSError: the
        move failed (the probes are then read again only after 1000 periods)."""
        if now_ns < self.due_ns:
            return None
        self.due_ns = now_ns + PERIOD_NS
        counts = self.counts()
        best = max(range(self.ncpu), key=counts.__getitem__)
        if not counts[best] or best == self.cpu or best not in self.allowed:
            return None
        if self.cpu is not None and counts[best] <= counts[self.cpu]:
            return None  # a tie keeps the daemon where it is
        try:
            os.sched_setaffinity(0, {best})
        except OSError:
            self.due_ns = now_ns + 1000 * PERIOD_NS
            raise
        self.cpu = best
        self.moves += 1
        return best

    def close(self) -> None:
        for s in self.probes:
            s.close()
        self.probes = []
