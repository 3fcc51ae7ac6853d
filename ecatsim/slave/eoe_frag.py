"""EoE fragmentation: Ethernet frames split into mailbox-sized fragments and put back.

A frame travels as fragments 0, 1, 2 ... of one frame number (4 bits, wrapping). Every
fragment but the last carries a multiple of 32 bytes; fragment 0's offset field holds the
whole frame size in 32-byte units rounded up, the others their offset in the frame in
32-byte units. The last fragment may carry a 4-byte time stamp after the data (time
appended). A fragment that does not continue the frame in progress drops that frame.
Ref: ETG.1000.6 §5.7 (EoE fragment header and fragmentation rules).
"""

from __future__ import annotations

from dataclasses import dataclass

from ecatsim.wire.eoe import BLOCK, MAX_FRAME, TIME_LEN, EoeHeader, fragment_header

#: the shortest frame worth handing on: an Ethernet header
MIN_FRAME = 14


@dataclass(slots=True)
class FragCounters:
    """What one direction has seen: fragments, whole frames, frames dropped."""

    fragments: int = 0
    frames: int = 0
    dropped: int = 0


class Reassembler:
    """Puts the master's fragments back into Ethernet frames (one frame at a time)."""

    def __init__(self) -> None:
        self.counters = FragCounters()
        self.buf = bytearray()
        self.size = 0
        self.frame = 0
        #: the fragment number expected next; 0: no frame in progress
        self.expect = 0

    def _lose(self, last: bool) -> None:
        """Drop the frame in progress (counted once); skip the rest of its fragments."""
        self.counters.dropped += 1
        self.buf = bytearray()
        self.expect = 0 if last else -1

    def feed(self, h: EoeHeader, data: bytes) -> bytes | None:
        """One fragment (``data``: the bytes after the EoE header); the whole frame when
        this fragment completes one, else None."""
        self.counters.fragments += 1
        if h.fragment == 0:
            if self.expect > 0:
                self.counters.dropped += 1  # a new frame: the one in progress is lost
            self.size = h.offset * BLOCK
            self.frame = h.frame
            self.buf = bytearray()
        elif self.expect < 0:
            if h.last:
                self.expect = 0  # the end of a frame already counted as dropped
            return None
        elif (
            self.expect == 0
            or h.fragment != self.expect
            or h.frame != self.frame
            or h.offset * BLOCK != len(self.buf)
        ):
            self._lose(h.last)
            return None
        if h.last and h.time_appended:
            if len(data) < TIME_LEN:
                self._lose(True)
                return None
            data = data[:-TIME_LEN]
        self.buf += data
        if len(self.buf) > self.size:
            self._lose(h.last)
            return None
        if not h.last:
            self.expect = h.fragment + 1
            return None
        frame = bytes(self.buf)
        self.expect = 0
        self.buf = bytearray()
        if len(frame) < MIN_FRAME:
            self.counters.dropped += 1
            return None
        self.counters.frames += 1
        return frame


class Fragmenter:
    """Splits one frame into fragments of at most ``room`` data bytes each."""

    def __init__(
        self, frame: bytes, frame_no: int, room: int, port: int = 0, timestamp: int | None = None
    ) -> None:
        if len(frame) > MAX_FRAME:
            raise ValueError(f"frame of {len(frame)} bytes: EoE carries at most {MAX_FRAME}")
        self.chunk = (room // BLOCK) * BLOCK
        if self.chunk == 0:
            raise ValueError(f"{room} data bytes per fragment: less than one 32-byte block")
        self.frame = frame
        self.frame_no = frame_no & 0x0F
        self.room = room
        self.port = port
        self.timestamp = timestamp
        self.pos = 0
        self.number = 0

    @property
    def done(self) -> bool:
        return self.number > 0 and self.pos >= len(self.frame)

    def next(self) -> bytes:
        """The next fragment: EoE header and data."""
        rest = len(self.frame) - self.pos
        tail = TIME_LEN if self.timestamp is not None else 0
        last = rest + tail <= self.room
        n = rest if last else self.chunk
        offset = (len(self.frame) + BLOCK - 1) // BLOCK if self.number == 0 else self.pos // BLOCK
        hdr = fragment_header(
            fragment=self.number,
            offset=offset,
            frame=self.frame_no,
            last=last,
            port=self.port,
            time_appended=last and tail > 0,
        )
        data = self.frame[self.pos : self.pos + n]
        if last and self.timestamp is not None:
            data += (self.timestamp & 0xFFFFFFFF).to_bytes(TIME_LEN, "little")
        self.pos += n
        self.number += 1
        if last:
            self.pos = len(self.frame)
        return hdr + data
