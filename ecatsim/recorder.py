"""A small in-memory recorder of the last frames, for diagnostics when something fails.

Slots are preallocated; recording is one slice copy (no per-frame objects).
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
        self._lens = [0] * depth
        self._next = 0

    def record(self, buf: bytearray | memoryview, n: int) -> None:
        i = self._next
        n = min(n, SLOT)
        self._slots[i][:n] = buf[:n]
        self._lens[i] = n
        self._next = (i + 1) % self.depth

    def last(self) -> list[bytes]:
        """Recorded frames, oldest first."""
        out = []
        for k in range(self.depth):
            i = (self._next + k) % self.depth
            if self._lens[i]:
                out.append(bytes(self._slots[i][: self._lens[i]]))
        return out

    def hexdump(self, limit: int = 4) -> list[str]:
        return [f.hex() for f in self.last()[-limit:]]
