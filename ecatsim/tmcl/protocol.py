"""TMCL binary telegrams: 9-byte commands and replies, checksum, status codes.

Ref: TMCM-1311 TMCL firmware manual §4.1 (command format), §4.1.1 (checksum), §4.2 (reply
format), §4.2.1 (status codes), §5.7.39 (the version string reply without checksum).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

#: one command or reply on RS485/USB: address, command, type, motor/bank, value, checksum
FRAME_LEN = 9

# Status codes (§4.2.1)
OK = 100
LOADED = 101
WRONG_CHECKSUM = 1
INVALID_COMMAND = 2
WRONG_TYPE = 3
INVALID_VALUE = 4
EEPROM_LOCKED = 5
NOT_AVAILABLE = 6
#: the status of the second reply of command 138 (§5.7.37)
EVENT = 128

STATUS_TEXT = {
    OK: "successfully executed, no error",
    LOADED: "command loaded into TMCL program EEPROM",
    WRONG_CHECKSUM: "wrong checksum",
    INVALID_COMMAND: "invalid command",
    WRONG_TYPE: "wrong type",
    INVALID_VALUE: "invalid value",
    EEPROM_LOCKED: "configuration EEPROM locked",
    NOT_AVAILABLE: "command not available",
}

# Command numbers (§5.1-5.6, §5.7)
ROR, ROL, MST, MVP = 1, 2, 3, 4
SAP, GAP, STAP, RSAP = 5, 6, 7, 8
SGP, GGP, STGP, RSGP = 9, 10, 11, 12
RFS, SIO, GIO = 13, 14, 15
CALC, COMP, JC, JA, CSUB, RSUB = 19, 20, 21, 22, 23, 24
EI, DI, WAIT, STOP = 25, 26, 27, 28
SCO, GCO, CCO, CALCX, AAP, AGP, CLE, VECT, RETI, ACO = 30, 31, 32, 33, 34, 35, 36, 37, 38, 39
UF0, UF7 = 64, 71
# Control functions (§5.7.37, §5.7.39, §4.3)
STOP_APP, RUN_APP, STEP_APP, RESET_APP = 128, 129, 130, 131
DOWNLOAD_START, DOWNLOAD_END, READ_MEMORY, APP_STATUS = 132, 133, 134, 135
FIRMWARE_VERSION, FACTORY_DEFAULTS, TARGET_EVENT, ASCII_MODE = 136, 137, 138, 139

MNEMONIC = {
    ROR: "ROR",
    ROL: "ROL",
    MST: "MST",
    MVP: "MVP",
    SAP: "SAP",
    GAP: "GAP",
    STAP: "STAP",
    RSAP: "RSAP",
    SGP: "SGP",
    GGP: "GGP",
    STGP: "STGP",
    RSGP: "RSGP",
    RFS: "RFS",
    SIO: "SIO",
    GIO: "GIO",
    CALC: "CALC",
    COMP: "COMP",
    JC: "JC",
    JA: "JA",
    CSUB: "CSUB",
    RSUB: "RSUB",
    EI: "EI",
    DI: "DI",
    WAIT: "WAIT",
    STOP: "STOP",
    SCO: "SCO",
    GCO: "GCO",
    CCO: "CCO",
    CALCX: "CALCX",
    AAP: "AAP",
    AGP: "AGP",
    CLE: "CLE",
    VECT: "VECT",
    RETI: "RETI",
    ACO: "ACO",
    **{UF0 + i: f"UF{i}" for i in range(8)},
}


def checksum(data: bytes) -> int:
    """The 8-bit sum of ``data`` (§4.1.1)."""
    return sum(data) & 0xFF


def to_signed(value: int) -> int:
    """A 32-bit field as the signed value the module computes with."""
    value &= 0xFFFFFFFF
    return value - (1 << 32) if value & 0x80000000 else value


@dataclass(frozen=True, slots=True)
class Command:
    """One TMCL command: what a host sends, or one instruction of a program."""

    opcode: int
    type: int = 0
    motor: int = 0
    #: the value field as a signed 32-bit number
    value: int = 0

    def pack(self) -> bytes:
        """The seven bytes without address and checksum (as on CAN and in program memory)."""
        return struct.pack(">BBBI", self.opcode, self.type, self.motor, self.value & 0xFFFFFFFF)

    def __str__(self) -> str:
        name = MNEMONIC.get(self.opcode, str(self.opcode))
        return f"{name} {self.type}, {self.motor}, {self.value}"


@dataclass(frozen=True, slots=True)
class Request:
    """A received 9-byte command telegram (§4.1)."""

    address: int
    command: Command
    checksum_ok: bool


def decode(frame: bytes) -> Request:
    """Split a 9-byte telegram; the checksum is checked, not enforced."""
    if len(frame) != FRAME_LEN:
        raise ValueError(f"a TMCL telegram has {FRAME_LEN} bytes, not {len(frame)}")
    addr, op, typ, motor, value, csum = struct.unpack(">BBBBIB", frame)
    ok = checksum(frame[:8]) == csum
    return Request(addr, Command(op, typ, motor, to_signed(value)), ok)


def encode_command(address: int, cmd: Command) -> bytes:
    """A 9-byte command telegram (what a host sends; for tests and tools)."""
    body = bytes([address & 0xFF]) + cmd.pack()
    return body + bytes([checksum(body)])


def encode_reply(host: int, module: int, status: int, opcode: int, value: int) -> bytes:
    """A 9-byte reply telegram (§4.2): reply address, module address, status, command,
    value MSB first, checksum."""
    body = struct.pack(
        ">BBBBI", host & 0xFF, module & 0xFF, status & 0xFF, opcode & 0xFF, value & 0xFFFFFFFF
    )
    return body + bytes([checksum(body)])


def version_reply(host: int, version: str) -> bytes:
    """Command 136 type 0: the host address and the 8-character version string, no
    checksum (§5.7.39)."""
    text = version.encode("ascii")
    if len(text) != 8:
        raise ValueError("the version string has 8 characters")
    return bytes([host & 0xFF]) + text


@dataclass(frozen=True, slots=True)
class Reply:
    """What a module answers to one command (before framing)."""

    status: int
    value: int = 0
    #: raw bytes that replace the framed reply (136 type 0, 134)
    raw: bytes | None = None


#: the pause after which a serial receiver drops a partial telegram (decision T3)
SERIAL_GAP_NS = 20_000_000


class Framer:
    """Cuts a byte stream into 9-byte telegrams.

    Between telegrams a real module's receiver restarts after a pause in the byte stream;
    a partial telegram older than ``gap_ns`` is dropped when the next byte arrives
    (decision T3), so one lost or extra byte costs only the telegram it hit. A TCP stream
    has no timing (decision T25): its framer has no gap (``gap_ns`` None)."""

    __slots__ = ("_buf", "_last_ns", "dropped", "gap_ns")

    def __init__(self, gap_ns: int | None = SERIAL_GAP_NS) -> None:
        self._buf = bytearray()
        self._last_ns = 0
        self.gap_ns = gap_ns
        #: bytes thrown away as parts of incomplete telegrams
        self.dropped = 0

    def feed(self, data: bytes, now_ns: int) -> list[bytes]:
        """The complete telegrams ``data`` finishes, in order."""
        gap = self.gap_ns
        if self._buf and gap is not None and now_ns - self._last_ns > gap:
            self.dropped += len(self._buf)
            self._buf.clear()
        self._last_ns = now_ns
        self._buf += data
        n = len(self._buf) // FRAME_LEN * FRAME_LEN
        frames = [bytes(self._buf[i : i + FRAME_LEN]) for i in range(0, n, FRAME_LEN)]
        del self._buf[:n]
        return frames

    def take(self) -> bytes:
        """The bytes of an incomplete telegram (when the line leaves binary mode)."""
        data = bytes(self._buf)
        self._buf.clear()
        return data

    @property
    def pending(self) -> int:
        return len(self._buf)
