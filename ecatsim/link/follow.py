"""Run the daemon on the CPU the master's frames come from (decision K5).

A master polls for its reply right after sending, and many sleep between polls (KickCAT:
``recv`` with ``MSG_DONTWAIT``, then a 20 us nap, until its 2 ms deadline; no last try after
the deadline). On a busy host such a nap can end milliseconds late, and the reply that came
meanwhile is never read. On a veth pair or a local NIC the frame is delivered to the daemon
on the CPU that sent it; a real-time daemon woken on that same CPU preempts the master at
once and the reply is queued before the master's first poll, whatever else runs.

The CPU a frame arrived on comes from a packet fanout group (``PACKET_FANOUT_CPU``: each
frame goes to the member whose index is the receiving CPU, packet(7)): one probe socket per
CPU, each keeping one byte of each EtherCAT frame it gets. After each frame the daemon
drains the probes that hold frames and, when most came from another CPU than the one it
runs on, pins itself there (``sched_setaffinity``): a master that moves is followed from
its next frame on. A daemon with much work per cycle on the master's CPU drives the
scheduler to move the master away, again and again: more than ``CHASE_MOVES`` moves within
a second stop the following for ``CHASE_PAUSE_NS`` and give the daemon all its CPUs back.
Only while the daemon runs SCHED_FIFO: an ordinary task woken on the master's CPU would
wait behind it.
"""

from __future__ import annotations

import os
import select
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
#: after a failed move, how long the daemon stays where it is before it tries again
BACKOFF_NS = 10_000_000_000
#: more moves than this within one second are a chase: the following pauses
CHASE_MOVES = 20
CHASE_PAUSE_NS = 10_000_000_000
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
        self.allowed = os.sched_getaffinity(0)
        #: fanout members: frame on CPU c -> member c % ncpu, so one per CPU number
        self.ncpu = max(os.cpu_count() or 1, max(self.allowed) + 1)
        self.cpu: int | None = None  # where the daemon is pinned by us (None: not yet)
        #: no move before this time (after a failed one)
        self.due_ns = 0
        self.moves = 0
        self.pauses = 0
        self._window_ns = 0  # start of the second the recent moves are counted in
        self._window_moves = 0
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
        self._cpu_of = {s.fileno(): cpu for cpu, s in enumerate(self.probes)}
        self._poller = select.poll()
        for s in self.probes:
            self._poller.register(s, select.POLLIN)

    def counts(self) -> list[int]:
        """Frames that arrived on each CPU since the probes were last read (drained)."""
        out = [0] * self.ncpu
        for fd, _events in self._poller.poll(0):
            cpu = self._cpu_of[fd]
            probe = self.probes[cpu]
            n = 0
            while True:
                try:
                    probe.recv_into(self._buf)
                except (BlockingIOError, InterruptedError):
                    break
                n += 1
            out[cpu] = n
        return out

    def poll(self, now_ns: int) -> int | None:
        """Pin the daemon to the CPU most frames came from since the last call, if it may
        run there and is not there yet (a tie keeps it where it is). Returns the CPU it
        moved to, else None. OSError: the move failed; no other is tried for BACKOFF_NS."""
        counts = self.counts()  # read while paused too: a later move looks at new frames
        if now_ns < self.due_ns:
            return None
        best = max(range(self.ncpu), key=counts.__getitem__)
        if not counts[best] or best == self.cpu or best not in self.allowed:
            return None
        if self.cpu is not None and counts[best] <= counts[self.cpu]:
            return None
        try:
            os.sched_setaffinity(0, {best})
        except OSError:
            self.due_ns = now_ns + BACKOFF_NS
            raise
        self.cpu = best
        self.moves += 1
        if now_ns - self._window_ns > 1_000_000_000:
            self._window_ns, self._window_moves = now_ns, 0
        self._window_moves += 1
        if self._window_moves > CHASE_MOVES:
            self._pause(now_ns)
            return None
        return best

    def _pause(self, now_ns: int) -> None:
        """Stop following for CHASE_PAUSE_NS; the daemon may run on all its CPUs again."""
        self.pauses += 1
        self.cpu = None
        self.due_ns = now_ns + CHASE_PAUSE_NS
        self._window_moves = 0
        os.sched_setaffinity(0, self.allowed)

    def close(self) -> None:
        for s in self.probes:
            s.close()
        self.probes = []
