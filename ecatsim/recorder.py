"""A small in-memory recorder of the last frames, for diagnostics when something fails.

Slots are preallocated; recording is one copy into the next slot (no per-frame objects).
Part of the compiled core (``recorder.pxd``): the daemon's compiled responder copies each
frame as received into the next slot, before processing it, with no Python call.
A failure is logged once, with the last frames.
"""

from __future__ import annotations

SLOT = 1536


class FrameRecorder:
    """Ring buffer of the last ``depth`` frames."""

    __slots__ = ("_lens", "_next", "_slots", "depth")

    def __init__(self, depth: int = 16) -> None:
        self.depth = depth
        self._slots = [bytearray(SLOT) for _ in range(depth)]
        #: each slot's length, two bytes little-endian (no Python integer per frame)
        self._lens = bytearray(2 * depth)
        self._next = 0

    def record(self, buf: bytearray | memoryview, n: int) -> None:
        """Keep ``buf[:n]`` (at most ``SLOT`` bytes) as the newest frame."""
        n = min(n, SLOT)
        self.next_slot()[:n] = buf[:n]
        self.commit(n)

    def next_slot(self) -> bytearray:
        """The slot the next frame goes into (the compiled responder copies a frame into
        it, then calls :meth:`commit`)."""
        return self._slots[self._next]

    def commit(self, n: int) -> None:
        """The frame in :meth:`next_slot` is ``n`` bytes long: it becomes the newest."""
        i = self._next
        n = min(n, SLOT)
        self._lens[2 * i] = n & 0xFF
        self._lens[2 * i + 1] = n >> 8
        self._next = i + 1 if i + 1 < self.depth else 0

    def last(self) -> list[bytes]:
        """Recorded frames, oldest first."""
        out = []
        for k in range(self.depth):
            i = (self._next + k) % self.depth
            n = self._lens[2 * i] | (self._lens[2 * i + 1] << 8)
            if n:
                out.append(bytes(self._slots[i][:n]))
        return out

    def hexdump(self, limit: int = 4) -> list[str]:
        return [f.hex() for f in self.last()[-limit:]]
