"""Mailbox, CoE and SDO headers.

Mailbox header (6 bytes): length u16 (bytes after the header), address u16,
channel (bits 0-5) + priority (bits 6-7) u8, type (bits 0-3) + counter (bits 4-6) u8.
CoE header (2 bytes): number (bits 0-8), service (bits 12-15).
Ref: ETG.1000.4 §5.6 (mailbox), ETG.1000.6 §5.6 (CoE, SDO, SDO Information).
"""

from __future__ import annotations

import struct
from enum import IntEnum

MBX_HEADER = struct.Struct("<HHBB")
MBX_HEADER_LEN = 6
COE_HEADER = struct.Struct("<H")
#: CoE header + SDO command, index, subindex, 4 data bytes
SDO = struct.Struct("<HBHBI")
SDO_LEN = 10
SDO_INFO = struct.Struct("<HBBH")  # CoE header, opcode(+incomplete), reserved, fragments left


class MbxType(IntEnum):
    """Mailbox types. Ref: ETG.1000.4 Table 29."""

    ERR = 0
    AOE = 1
    EOE = 2
    COE = 3
    FOE = 4
    SOE = 5
    VOE = 15


class CoeService(IntEnum):
    """CoE services. Ref: ETG.1000.6 Table 29."""

    EMERGENCY = 1
    SDO_REQUEST = 2
    SDO_RESPONSE = 3
    TXPDO = 4
    RXPDO = 5
    TXPDO_RR = 6
    RXPDO_RR = 7
    SDO_INFO = 8


class MbxError(IntEnum):
    """Mailbox error reply codes. Ref: ETG.1000.4 Table 30."""

    SYNTAX = 0x0001
    UNSUPPORTED_PROTOCOL = 0x0002
    INVALID_CHANNEL = 0x0003
    SERVICE_NOT_SUPPORTED = 0x0004
    INVALID_HEADER = 0x0005
    SIZE_TOO_SHORT = 0x0006
    NO_MORE_MEMORY = 0x0007
    INVALID_SIZE = 0x0008


def mbx_header(length: int, mtype: int, counter: int, address: int = 0, channel: int = 0) -> bytes:
    """Pack a mailbox header. Ref: ETG.1000.4 §5.6 Table 28."""
    return MBX_HEADER.pack(length, address, channel & 0x3F, (mtype & 0x0F) | ((counter & 7) << 4))
