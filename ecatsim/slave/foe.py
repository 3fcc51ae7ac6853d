"""File access over EtherCAT: firmware files written and read in BOOT.

Files live in a configurable directory (written atomically) or in memory. Writes are
accepted only in BOOT (TMC8670 §2.3, §3.2: firmware update via FoE in bootstrap).
Ref: ETG.1000.6 §5.8 (FoE: RRQ/WRQ/DATA/ACK/ERR/BUSY, error codes Table 92).
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from pathlib import Path

import structlog

from ecatsim.files import atomic_write
from ecatsim.slave.al import AlState
from ecatsim.slave.mailbox import MailboxError, Request
from ecatsim.wire.mailbox import MbxError, MbxType

log = structlog.get_logger("ecatsim.foe")

OP_RRQ, OP_WRQ, OP_DATA, OP_ACK, OP_ERR, OP_BUSY = 1, 2, 3, 4, 5, 6
HDR = struct.Struct("<BBI")  # opcode, reserved, password / packet number / error code

# FoE error codes. Ref: ETG.1000.6 Table 92.
ERR_NOT_DEFINED = 0x8000
ERR_NOT_FOUND = 0x8001
ERR_ACCESS = 0x8002
ERR_DISK_FULL = 0x8003
ERR_ILLEGAL = 0x8004
ERR_PACKET_NUMBER = 0x8005
ERR_NOT_IN_BOOTSTRAP = 0x8009
ERR_NO_RIGHTS = 0x800A
MAX_FILE = 4 * 1024 * 1024
_SAFE = re.compile(r"^[A-Za-z0-9._-]{1,64}$")


class FoeError(Exception):
    def __init__(self, code: int, text: str) -> None:
        super().__init__(text)
        self.code = code


class FoeServer:
    """One FoE server: a write or read transfer at a time."""

    def __init__(
        self,
        state: Callable[[], int],
        max_body: Callable[[], int],
        directory: Path | None = None,
        password: int = 0,
    ) -> None:
        self.state = state
        self.max_body = max_body
        self.directory = directory
        self.password = password
        self.files: dict[str, bytes] = {}
        self.wname: str | None = None
        self.wbuf = bytearray()
        self.wpacket = 0
        self.rdata = b""
        self.rpacket = 0
        self.rdone = True

    # ----------------------------------------------------------------- storage

    def _store(self, name: str, data: bytes) -> None:
        if self.directory is None:
            self.files[name] = data
            return
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            atomic_write(self.directory / name, data)
        except OSError as exc:
            raise FoeError(ERR_DISK_FULL, f"cannot store {name}: {exc.strerror}") from exc

    def _load(self, name: str) -> bytes:
        if self.directory is None:
            if name not in self.files:
                raise FoeError(ERR_NOT_FOUND, f"{name}: not found")
            return self.files[name]
        try:
            return (self.directory / name).read_bytes()
        except OSError as exc:
            raise FoeError(ERR_NOT_FOUND, f"{name}: not found") from exc

    # ----------------------------------------------------------------- protocol

    def handle(self, req: Request) -> list[tuple[int, bytes]]:
        """One FoE mailbox; errors become an FoE ERR packet here (one place)."""
        if len(req.data) < HDR.size:
            raise MailboxError(MbxError.SIZE_TOO_SHORT)
        op, _r, arg = HDR.unpack_from(req.data)
        body = req.data[HDR.size :]
        try:
            if op == OP_WRQ:
                return self._wrq(arg, body)
            if op == OP_DATA:
                return self._data(arg, body)
            if op == OP_RRQ:
                return self._rrq(arg, body)
            if op == OP_ACK:
                return self._ack(arg)
            if op == OP_ERR:
                self._reset()
                return []
            raise FoeError(ERR_ILLEGAL, f"opcode {op}")
        except FoeError as exc:
            self._reset()
            log.info("foe_error", code=f"0x{exc.code:04X}", text=str(exc))
            text = str(exc).encode()[: max(0, self.max_body() - HDR.size)]
            return [(MbxType.FOE, HDR.pack(OP_ERR, 0, exc.code) + text)]

    def _reset(self) -> None:
        self.wname = None
        self.wbuf = bytearray()
        self.rdata = b""
        self.rdone = True

    def _name(self, body: bytes) -> str:
        name = body.split(b"\x00", 1)[0].decode("latin-1")
        if not _SAFE.match(name) or name in (".", ".."):
            raise FoeError(ERR_ILLEGAL, f"file name {name!r} not allowed")
        return name

    def _check_password(self, password: int) -> None:
        if self.password and password != self.password:
            raise FoeError(ERR_NO_RIGHTS, "wrong password")

    def _wrq(self, password: int, body: bytes) -> list[tuple[int, bytes]]:
        """Write request: only in BOOT. Ref: ETG.1000.6 §5.8; TMC8670 §3.2."""
        name = self._name(body)
        self._check_password(password)
        if self.state() != int(AlState.BOOT):
            raise FoeError(ERR_NOT_IN_BOOTSTRAP, "file writes are accepted in BOOT only")
        self.wname = name
        self.wbuf = bytearray()
        self.wpacket = 0
        return [(MbxType.FOE, HDR.pack(OP_ACK, 0, 0))]

    def _data(self, packet: int, body: bytes) -> list[tuple[int, bytes]]:
        if self.wname is None:
            raise FoeError(ERR_ILLEGAL, "DATA without a write request")
        if packet != self.wpacket + 1:
            raise FoeError(ERR_PACKET_NUMBER, f"packet {packet}, expected {self.wpacket + 1}")
        self.wpacket = packet
        self.wbuf += body
        if len(self.wbuf) > MAX_FILE:
            raise FoeError(ERR_DISK_FULL, "file too large")
        if len(body) < self.max_body() - HDR.size:  # a short packet ends the file
            name = self.wname
            self._store(name, bytes(self.wbuf))
            log.info("foe_written", file=name, size=len(self.wbuf))
            self.wname = None
        return [(MbxType.FOE, HDR.pack(OP_ACK, 0, packet))]

    def _rrq(self, password: int, body: bytes) -> list[tuple[int, bytes]]:
        name = self._name(body)
        self._check_password(password)
        self.rdata = self._load(name)
        self.rpacket = 0
        self.rdone = False
        return self._next_data()

    def _next_data(self) -> list[tuple[int, bytes]]:
        room = self.max_body() - HDR.size
        chunk = self.rdata[:room]
        self.rdata = self.rdata[room:]
        self.rpacket += 1
        if len(chunk) < room:
            self.rdone = True
        return [(MbxType.FOE, HDR.pack(OP_DATA, 0, self.rpacket) + chunk)]

    def _ack(self, packet: int) -> list[tuple[int, bytes]]:
        if self.rdone:
            return []
        if packet != self.rpacket:
            raise FoeError(ERR_PACKET_NUMBER, f"ack {packet}, expected {self.rpacket}")
        return self._next_data()
