"""Run the daemon on the CPU the master's frames come from (decision K5).

A master polls for its reply right after sending, and many sleep between polls (KickCAT:
``recv`` with ``MSG_DONTWAIT``, then a 20 us nap, until its 2 ms deadline; no last try after
the deadline). On a busy host such a nap can end milliseconds late, and the reply that came
meanwhile is never read. On a veth pair or a local NIC the frame is delivered to the daemon
on the CPU that sent it; a real-time daemon woken on that same CPU preempts the master at
once and the reply is queued before the master's first poll, whatever else runs.

The CPU a frame arrived on comes from a packet fanout group (``PACKET_FANOUT_CPU``: each
frame goes to the member whose index is the receiving CPU, packet(7)): one probe socket per
CPU, each keeping one byte of each EtherCAT frame it gets. The probes of the CPUs the daemon
is not pinned to are members of an epoll(7) set (:meth:`CpuFollower.fileno`), which the
daemon's wait watches: as long as the frames arrive on its own CPU nothing more happens per
frame. When one arrives elsewhere the set becomes readable and the daemon calls
:meth:`CpuFollower.poll`, which drains every probe and pins the daemon
(``sched_setaffinity``) to the other CPU most frames came from: a master that moves is
followed from its next frame on. A daemon with much work per cycle on the master's CPU
drives the scheduler to move the master away, again and again: more than ``CHASE_MOVES``
moves within a second stop the following for ``CHASE_PAUSE_NS`` and give the daemon all its
CPUs back, and so does a daemon that used more than ``BUSY_SHARE`` of a CPU since its last
look (a large segment's SYNC0 work): on the master's CPU it would leave the master too
little of it, and a master that runs late loses frames however fast the replies come; while
stopped (and for ``BACKOFF_NS`` after a failed move) no probe is watched,
and the daemon looks again at :attr:`CpuFollower.look_ns`. Only while the daemon runs
SCHED_FIFO: an ordinary task woken on the master's CPU would wait behind it.
"""

from __future__ import annotations

import os
import select
import socket
import time
from collections.abc import Callable

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
#: a daemon that used more than this share of a CPU since its last look (measured over at
#: least BUSY_WINDOW_NS) does not follow, and pauses as after a chase
BUSY_SHARE = 0.5
BUSY_WINDOW_NS = 100_000_000
#: each probe's receive buffer (the kernel doubles it): a few dozen one-byte frames. The
#: probe of the daemon's own CPU is read only when a frame comes from elsewhere; until then
#: it fills and drops, and what it holds is drained at that look.
PROBE_BUF = 1 << 14

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
        #: the daemon's CPU time (ns; process-wide), and the host time and CPU time of the
        #: start of the window its busy share is measured over (0: not started)
        self.cpu_time: Callable[[], int] = time.process_time_ns
        self._busy_t = 0
        self._busy_cpu = 0
        #: pauses because the daemon was busier than BUSY_SHARE
        self.busy_pauses = 0
        self._buf = bytearray(1)
        self.probes: list[socket.socket] = []
        #: the probes whose frames call for a look (:meth:`fileno`), by CPU
        self._epoll = select.epoll()
        self._watched: set[int] = set()
        #: while the following is stopped: when the daemon should look again (0: not stopped)
        self.look_ns = 0
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
        self._watch()

    def fileno(self) -> int:
        """An epoll(7) descriptor, readable when a frame has arrived on a CPU the daemon may
        run on other than the one it is pinned to (any before the first move) and the
        following is not stopped: the daemon calls :meth:`poll` then."""
        return self._epoll.fileno()

    def _watch(self) -> None:
        """Watch the probes of the CPUs the daemon may move to, or none while the following
        is stopped (``look_ns`` set)."""
        want = set() if self.look_ns else {c for c in self.allowed if c != self.cpu}
        for cpu in self._watched - want:
            self._epoll.unregister(self.probes[cpu])
        for cpu in want - self._watched:
            self._epoll.register(self.probes[cpu], select.EPOLLIN)
        self._watched = want

    def _stop_until(self, due_ns: int) -> None:
        """No look before ``due_ns``: nothing is watched until then."""
        self.due_ns = self.look_ns = due_ns
        self._watch()

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
        """Drain the probes and, if frames came from CPUs other than the daemon's own since
        the last look, pin it to the one most came from (the lowest of a tie) if it may run
        there. Returns the CPU it moved to, else None. OSError: the move failed; no other is
        tried for BACKOFF_NS."""
        counts = self.counts()  # read while stopped too: a later move looks at new frames
        if now_ns < self.due_ns:
            return None
        if self.look_ns:
            self.look_ns = 0
            self._watch()
        best = max(
            (c for c in range(self.ncpu) if c != self.cpu and c in self.allowed),
            key=counts.__getitem__,
            default=None,
        )
        if best is None or not counts[best]:
            return None
        if self.busy(now_ns):
            self.busy_pauses += 1
            self._pause(now_ns)
            return None
        try:
            os.sched_setaffinity(0, {best})
        except OSError:
            self._stop_until(now_ns + BACKOFF_NS)
            raise
        self.cpu = best
        self.moves += 1
        if now_ns - self._window_ns > 1_000_000_000:
            self._window_ns, self._window_moves = now_ns, 0
        self._window_moves += 1
        if self._window_moves > CHASE_MOVES:
            self._pause(now_ns)
            return None
        self._watch()
        return best

    def busy(self, now_ns: int) -> bool:
        """Whether the daemon used more than BUSY_SHARE of a CPU since the window began
        (at least BUSY_WINDOW_NS ago; a new window begins then). False while the window is
        shorter."""
        cpu = self.cpu_time()
        if not self._busy_t:
            self._busy_t, self._busy_cpu = now_ns, cpu
            return False
        dt = now_ns - self._busy_t
        if dt < BUSY_WINDOW_NS:
            return False
        share = (cpu - self._busy_cpu) / dt
        self._busy_t, self._busy_cpu = now_ns, cpu
        return share > BUSY_SHARE

    def _pause(self, now_ns: int) -> None:
        """Stop following for CHASE_PAUSE_NS; the daemon may run on all its CPUs again."""
        self.pauses += 1
        self.cpu = None
        self._window_moves = 0
        self._stop_until(now_ns + CHASE_PAUSE_NS)
        os.sched_setaffinity(0, self.allowed)

    def close(self) -> None:
        self._epoll.close()
        for s in self.probes:
            s.close()
        self.probes = []
