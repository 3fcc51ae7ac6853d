# cython: boundscheck=False, wraparound=False
# (compiled: the frame copy below has no index checks; every index is kept inside both
# buffers by the clamp before it)
"""A small in-memory recorder of the last frames, for diagnostics when something fails.

Slots are preallocated; recording is one copy into the next slot (no per-frame objects).
Part of the compiled core (``recorder.pxd``): the per-frame sequence (``sequence.py``)
copies each frame as received into the next slot, before processing it, with C calls.
A failure is logged once, with the last frames.
"""

from __future__ import annotations

SLOT = 1536


class FrameRecorder:
    """Ring buffer of the last ``depth`` frames."""

    __slots__ = ("_lens", "_next", "_ring", "_view", "depth")

    def __init__(self, depth: int = 16) -> None:
        self.depth = depth
        #: the slots, one after another, and a view of them (made once)
        self._ring = bytearray(SLOT * depth)
        self._view = memoryview(self._ring)
        #: each slot's length, two bytes little-endian (no Python integer per frame)
        self._lens = bytearray(2 * depth)
        self._next = 0

    def record(self, buf: bytearray | memoryview, n: int) -> None:
        """Keep ``buf[:n]`` (at most ``SLOT`` bytes) as the newest frame: one copy into the
        next slot (compiled: a copy between typed views, memcpy where both are contiguous,
        not a loop per byte; decision P60)."""
        i = self._next
        n = min(n, SLOT, len(buf))
        ring = self._view
        base = i * SLOT
        if n > 0:
            ring[base : base + n] = buf[:n]
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
                out.append(bytes(self._ring[i * SLOT : i * SLOT + n]))
        return out

    def hexdump(self, limit: int = 4) -> list[str]:
        return [f.hex() for f in self.last()[-limit:]]
