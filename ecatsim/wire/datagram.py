"""EtherCAT datagram (DLPDU) header layout and command codes.

A datagram is: cmd(1) idx(1) address(4) len/flags(2) irq(2) data(len) wkc(2).
Ref: ETG.1000.4 §5.4 (DLPDU structure), Table 11 (command types).
"""

from __future__ import annotations

import struct
from enum import IntEnum

HEADER_LEN = 10
WKC_LEN = 2
#: Overhead of one datagram beyond its data.
OVERHEAD = HEADER_LEN + WKC_LEN

#: cmd, idx, adp, ado, len/flags, irq
HEADER = struct.Struct("<BBHHHH")
#: cmd, idx, logical address, len/flags, irq
HEADER_LOGICAL = struct.Struct("<BBIHH")
U16 = struct.Struct("<H")

LEN_MASK = 0x07FF
CIRCULATING = 0x4000
MORE_FOLLOWS = 0x8000


class Cmd(IntEnum):
    """EtherCAT command types. Ref: ETG.1000.4 Table 11."""

    NOP = 0
    APRD = 1
    APWR = 2
    APRW = 3
    FPRD = 4
    FPWR = 5
    FPRW = 6
    BRD = 7
    BWR = 8
    BRW = 9
    LRD = 10
    LWR = 11
    LRW = 12
    ARMW = 13
    FRMW = 14


# The same codes as plain ints, for the compiled frame walk (C constants there).
NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW = (
    int(c) for c in Cmd
)


def build(
    cmd: int,
    adp: int,
    ado: int,
    data: bytes,
    *,
    idx: int = 0,
    more: bool = False,
    circulating: bool = False,
    irq: int = 0,
    wkc: int = 0,
) -> bytes:
    """Build one datagram (for tests and tools, not the hot path).

    Ref: ETG.1000.4 §5.4.
    """
    lf = len(data) & LEN_MASK
    if more:
        lf |= MORE_FOLLOWS
    if circulating:
        lf |= CIRCULATING
    return HEADER.pack(cmd, idx, adp, ado, lf, irq) + data + U16.pack(wkc)


def build_logical(
    cmd: int, lad: int, data: bytes, *, idx: int = 0, more: bool = False, wkc: int = 0
) -> bytes:
    """Build one logical-addressed datagram (LRD/LWR/LRW). Ref: ETG.1000.4 §5.4."""
    lf = (len(data) & LEN_MASK) | (MORE_FOLLOWS if more else 0)
    return HEADER_LOGICAL.pack(cmd, idx, lad, lf, 0) + data + U16.pack(wkc)


def ecat_frame(datagrams: list[bytes], *, frame_type: int = 1) -> bytes:
    """EtherCAT header + datagrams (the UDP payload form). Ref: ETG.1000.4 §5.3."""
    body = b"".join(datagrams)
    return U16.pack((len(body) & LEN_MASK) | (frame_type << 12)) + body


def ethernet_frame(
    datagrams: list[bytes], *, src: bytes = b"\x00\x00\x00\x00\x00\x01", vlan: int | None = None
) -> bytes:
    """A whole Ethernet frame carrying EtherCAT (broadcast destination, like SOEM)."""
    hdr = b"\xff" * 6 + src
    if vlan is not None:
        hdr += struct.pack(">HH", 0x8100, vlan)
    return hdr + b"\x88\xa4" + ecat_frame(datagrams)
