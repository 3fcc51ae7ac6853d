"""In-process loopback link for tests: two queues instead of a wire.

The test plays the master with ``master_send`` / ``master_recv``; the daemon side is an
ordinary :class:`~ecatsim.link.base.Link`. There is no file descriptor behind it
(``fileno`` returns -1), so ``Daemon.run`` (which polls a descriptor) cannot serve it:
an in-process test drives the daemon directly, calling ``Daemon.handle_one(buf)`` (or
``link.recv_into`` + ``segment.process``) after each ``master_send``.

A :class:`Manipulator` attached to either direction drops, duplicates, corrupts or delays
frames with a seeded :class:`random.Random`, so a run is reproducible from its seed. A delay
is counted in *polls* of the receiving side (calls to ``recv_into`` or ``master_recv``).

Ref: docs/architecture.md (link layer); ETG.1000.4 (a master must cope with lost frames,
which it detects by the frame index and working counter).
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass, field

#: Upper bound of frames queued in one direction; older frames are dropped beyond it, as a
#: full socket buffer would.
QUEUE_LIMIT = 1024


@dataclass(slots=True)
class ManipulatorStats:
    """What a Manipulator did so far."""

    seen: int = 0
    dropped: int = 0
    duplicated: int = 0
    corrupted: int = 0
    delayed: int = 0


@dataclass(slots=True)
class Manipulator:
    """Seeded frame mangler. Probabilities are per frame, checked in the order
    drop, corrupt, duplicate, delay (a dropped frame is not also corrupted).

    ``corrupt_from`` is the first byte offset a corruption may hit (e.g. 14 keeps the
    Ethernet header intact so the frame still reaches the EtherCAT code).
    ``delay_polls`` is how many receiver polls a delayed frame is held back.
    """

    seed: int = 0
    drop: float = 0.0
    duplicate: float = 0.0
    corrupt: float = 0.0
    delay: float = 0.0
    delay_polls: int = 1
    corrupt_from: int = 0
    stats: ManipulatorStats = field(default_factory=ManipulatorStats)
    rng: random.Random = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("drop", "duplicate", "corrupt", "delay"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"Manipulator.{name}={p}: a probability in 0..1")
        if self.delay_polls < 0 or self.corrupt_from < 0:
            raise ValueError("Manipulator: delay_polls and corrupt_from must be >= 0")
        self.rng = random.Random(self.seed)

    def apply(self, frame: bytes) -> list[tuple[int, bytes]]:
        """The frames to deliver for ``frame`` as (delay in polls, bytes); [] if dropped."""
        rng = self.rng
        self.stats.seen += 1
        if self.drop and rng.random() < self.drop:
            self.stats.dropped += 1
            return []
        if self.corrupt and rng.random() < self.corrupt and len(frame) > self.corrupt_from:
            pos = rng.randrange(self.corrupt_from, len(frame))
            b = bytearray(frame)
            b[pos] ^= rng.randrange(1, 256)
            frame = bytes(b)
            self.stats.corrupted += 1
        copies = 1
        if self.duplicate and rng.random() < self.duplicate:
            copies = 2
            self.stats.duplicated += 1
        wait = 0
        if self.delay and rng.random() < self.delay:
            wait = self.delay_polls
            self.stats.delayed += 1
        return [(wait, frame)] * copies


class _Direction:
    """One direction of the loopback: frames with the poll number they become visible at."""

    __slots__ = ("manipulator", "polls", "queue")

    def __init__(self, manipulator: Manipulator | None) -> None:
        self.manipulator = manipulator
        self.queue: deque[tuple[int, bytes]] = deque(maxlen=QUEUE_LIMIT)
        self.polls = 0

    def put(self, frame: bytes) -> None:
        if self.manipulator is None:
            self.queue.append((0, frame))
            return
        for wait, f in self.manipulator.apply(frame):
            # visible from the (wait+1)-th poll after now
            self.queue.append((self.polls + wait, f))

    def get(self) -> bytes | None:
        """The oldest frame that is due at this poll (a delayed frame may be overtaken)."""
        self.polls += 1
        q = self.queue
        for i, (due, frame) in enumerate(q):
            if due < self.polls:
                del q[i]
                return frame
        return None


class LoopbackLink:
    """Daemon side of an in-process wire; the test is the master on the other side."""

    ethernet = True
    rx_ns = 0

    def __init__(
        self,
        *,
        ethernet: bool = True,
        to_slave: Manipulator | None = None,
        to_master: Manipulator | None = None,
    ) -> None:
        self.ethernet = ethernet
        self._to_slave = _Direction(to_slave)
        self._to_master = _Direction(to_master)
        self.closed = False

    # --- the master's side -------------------------------------------------------------
    def master_send(self, frame: bytes | bytearray | memoryview) -> None:
        """Put a frame on the wire towards the daemon."""
        self._to_slave.put(bytes(frame))

    def master_recv(self) -> bytes | None:
        """The next frame the daemon sent, or None (one poll of the master side)."""
        return self._to_master.get()

    def attach(
        self, *, to_slave: Manipulator | None = None, to_master: Manipulator | None = None
    ) -> None:
        """Attach (or, with None, remove) manipulators for frames sent after this call."""
        self._to_slave.manipulator = to_slave
        self._to_master.manipulator = to_master

    @property
    def pending_to_slave(self) -> int:
        return len(self._to_slave.queue)

    @property
    def pending_to_master(self) -> int:
        return len(self._to_master.queue)

    # --- the daemon's side (Link) ------------------------------------------------------
    def fileno(self) -> int:
        """-1: nothing to poll. An in-process loop calls ``recv_into`` directly."""
        return -1

    def recv_into(self, buf: bytearray) -> int:
        if self.closed:
            return 0
        frame = self._to_slave.get()
        if frame is None:
            return 0
        n = min(len(frame), len(buf))  # a longer frame is truncated, as recv would
        with memoryview(buf) as mv:
            mv[:n] = frame[:n]
        return n

    def send(self, frame: memoryview) -> None:
        if not self.closed:
            self._to_master.put(bytes(frame))

    def close(self) -> None:
        self.closed = True
