"""LIN 1.3 framing as a master's UART sees it on the pty, and the byte-stream parser.

A frame is: break, sync 0x55, protected identifier (PID), then 2, 4 or 8 data bytes and
the classic checksum. A pty cannot carry a break, so the break arrives as the byte 0x00 a
UART receives for it (decision N1). The data length is coded in identifier bits 5:4
(LIN 1.3; TMC211 §6.9: "2, 4 or 8 data fields"). Frames a node publishes carry only the
header from the master; the node's answer is written back. Nothing the master writes is
echoed.

Errors go to the LIN error status register of TMC211 §6.7 Table 14: a wrong sync field,
a bad parity or noise where a header should start is a header error; a bad checksum is a
data error; a frame that stops before its checksum is a timeout error (decision N4).
"""

from __future__ import annotations

from enum import IntEnum, IntFlag
from typing import Protocol

BREAK = 0x00
SYNC = 0x55
#: reserved identifiers (TMC211 §6.8, §6.9.5, §6.9.6)
MASTER_REQUEST = 0x3C
SLAVE_RESPONSE = 0x3D
#: nominal header length in bit times (LIN 1.3: break 13, delimiter 1, sync 10, PID 10)
HEADER_BITS = 34
#: LIN 1.3 frame time tolerance: a frame may take 1.4 times its nominal length
FRAME_TOLERANCE = 1.4


class LinError(IntFlag):
    """The LIN error status register (TMC211 §6.7 Table 14)."""

    BIT = 0x01
    HEADER = 0x02
    DATA = 0x04
    TIMEOUT = 0x08


def protect(ident: int) -> int:
    """The protected identifier: ID5..0 with parity P0 (bit 6) and P1 (bit 7)."""
    i = ident & 0x3F
    p0 = (i ^ i >> 1 ^ i >> 2 ^ i >> 4) & 1
    p1 = ~(i >> 1 ^ i >> 3 ^ i >> 4 ^ i >> 5) & 1
    return i | p0 << 6 | p1 << 7


def unprotect(pid: int) -> int | None:
    """The identifier of a protected identifier, or None if its parity is wrong."""
    ident = pid & 0x3F
    return ident if protect(ident) == pid else None


def data_length(ident: int) -> int:
    """Data bytes of a frame by its identifier bits 5:4 (LIN 1.3): 2, 2, 4, 8."""
    return (2, 2, 4, 8)[ident >> 4 & 3]


def classic_checksum(data: bytes) -> int:
    """The classic checksum: the inverted 8-bit sum with carry of the data bytes."""
    s = 0
    for b in data:
        s += b
        if s > 0xFF:
            s -= 0xFF
    return ~s & 0xFF


def header(ident: int) -> bytes:
    """What a master writes to start a frame: break (0x00), sync, protected identifier."""
    return bytes((BREAK, SYNC, protect(ident)))


def frame(ident: int, data: bytes) -> bytes:
    """A complete master-published frame: header, data and classic checksum."""
    return header(ident) + data + bytes((classic_checksum(data),))


def response(data: bytes) -> bytes:
    """A node's answer to a header: data and classic checksum."""
    return data + bytes((classic_checksum(data),))


class FrameHandler(Protocol):
    """What the parser reports to (the bus)."""

    def on_header(self, ident: int, now_ns: int) -> bytes | None:
        """A valid header: the bytes a node answers with, or None if no node publishes."""
        ...

    def on_frame(self, ident: int, data: bytes, now_ns: int) -> None:
        """A complete master-published frame with a correct checksum."""
        ...

    def on_error(self, error: LinError, now_ns: int) -> None:
        """A frame was ignored for this error."""
        ...


class _St(IntEnum):
    IDLE = 0
    BREAK = 1
    SYNC = 2
    DATA = 3


class Parser:
    """The byte-stream state machine: bytes in (with their arrival time), answers out.

    A header or a frame that is not complete within its LIN 1.3 maximum time is dropped
    when the next byte arrives later than that, or at :meth:`expire`: so a master that
    waits out the response time after a header nobody answered is understood again."""

    def __init__(self, handler: FrameHandler, baud: int = 19200) -> None:
        self.handler = handler
        self.bit_ns = 1_000_000_000 / baud
        self._header_ns = int(FRAME_TOLERANCE * HEADER_BITS * self.bit_ns)
        self._state = _St.IDLE
        self._start_ns = 0
        self._deadline: int | None = None
        self._ident = 0
        self._need = 0
        self._data = bytearray()
        #: frames received and answered, errors by kind, stray bytes between frames
        self.frames = 0
        self.answered = 0
        self.errors: dict[str, int] = {e.name or "": 0 for e in LinError}
        self.noise = 0

    def frame_ns(self, ident: int) -> int:
        """T_frame_max of a frame with this identifier (LIN 1.3), in ns."""
        bits = HEADER_BITS + 10 * (data_length(ident) + 1)
        return int(FRAME_TOLERANCE * bits * self.bit_ns)

    def deadline_ns(self) -> int | None:
        """When the frame in progress times out, or None."""
        return self._deadline

    def _error(self, err: LinError, now_ns: int) -> None:
        self.errors[err.name or ""] += 1
        self._reset()
        self.handler.on_error(err, now_ns)

    def _reset(self) -> None:
        self._state = _St.IDLE
        self._deadline = None
        self._data.clear()

    def expire(self, now_ns: int) -> None:
        """Drop a header or frame whose time is over."""
        if self._deadline is None or now_ns < self._deadline:
            return
        if self._state == _St.DATA and not self._data:
            self._reset()  # a header nobody answered: no frame, no error (decision N4)
        else:
            self._error(LinError.TIMEOUT if self._state == _St.DATA else LinError.HEADER, now_ns)

    def feed(self, data: bytes, now_ns: int) -> bytes:
        """Bytes the master wrote; returns the bytes the nodes answer with."""
        out = bytearray()
        for b in data:
            if self._deadline is not None and now_ns >= self._deadline:
                self.expire(now_ns)
            st = self._state
            if st == _St.DATA:
                self._data.append(b)
                if len(self._data) == self._need + 1:
                    self._complete(now_ns)
            elif st == _St.IDLE:
                if b == BREAK:
                    self._state = _St.BREAK
                    self._start_ns = now_ns
                    self._deadline = now_ns + self._header_ns
                else:
                    self.noise += 1
                    self._error(LinError.HEADER, now_ns)
            elif st == _St.BREAK:
                if b == SYNC:
                    self._state = _St.SYNC
                elif b != BREAK:  # a long break reads as several 0x00
                    self._error(LinError.HEADER, now_ns)
            else:  # _St.SYNC: the protected identifier
                ident = unprotect(b)
                if ident is None:
                    self._error(LinError.HEADER, now_ns)
                    continue
                self._ident = ident
                answer = self.handler.on_header(ident, now_ns)
                if answer is not None:
                    self.frames += 1
                    self.answered += 1
                    out += answer
                    self._reset()
                else:
                    self._state = _St.DATA
                    self._need = data_length(ident)
                    self._deadline = self._start_ns + self.frame_ns(ident)
                    self._data.clear()
        return bytes(out)

    def _complete(self, now_ns: int) -> None:
        payload = bytes(self._data[:-1])
        if classic_checksum(payload) != self._data[-1]:
            self._error(LinError.DATA, now_ns)
            return
        self.frames += 1
        ident = self._ident
        self._reset()
        self.handler.on_frame(ident, payload, now_ns)
