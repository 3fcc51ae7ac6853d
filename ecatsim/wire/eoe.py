"""The EoE header (two 16-bit words after the mailbox header) and the IP parameter block.

Word 1: frame type (bits 0-3), port (4-7), last fragment (8), time appended (9),
time request (10). Word 2 of a data fragment: fragment number (bits 0-5), offset in
32-byte units (6-11; fragment 0: the whole frame size in 32-byte units, rounded up),
frame number (12-15). Word 2 of a control response: the result code.
IP parameter block: a 32-bit flags word, then the included fields in order (MAC 6 bytes,
IP, subnet mask, default gateway, DNS server 4 bytes each, octet-reversed; DNS name 32).
Ref: ETG.1000.6 §5.7 (EoE), Tables for the EoE header, Set IP Parameter and result codes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

EOE_HEADER = struct.Struct("<HH")
EOE_HEADER_LEN = 4
#: fragment offsets and sizes count in 32-byte blocks
BLOCK = 32
#: the largest frame the offset field of fragment 0 can announce (63 blocks)
MAX_FRAME = 63 * BLOCK
#: the time stamp a fragment may carry after its data (time appended)
TIME_LEN = 4
DNS_NAME_LEN = 32


class EoeType(IntEnum):
    """EoE frame types. Ref: ETG.1000.6 §5.7 (EoE header, frame type)."""

    FRAGMENT = 0
    TIMESTAMP = 1
    SET_IP_REQ = 2
    SET_IP_RESP = 3
    SET_FILTER_REQ = 4
    SET_FILTER_RESP = 5
    GET_IP_REQ = 6
    GET_IP_RESP = 7
    GET_FILTER_REQ = 8
    GET_FILTER_RESP = 9


class EoeResult(IntEnum):
    """EoE result codes. Ref: ETG.1000.6 §5.7 (EoE result parameter)."""

    SUCCESS = 0x0000
    UNSPECIFIED_ERROR = 0x0001
    UNSUPPORTED_FRAME_TYPE = 0x0002
    NO_IP_SUPPORT = 0x0201
    NO_DHCP_SUPPORT = 0x0202
    NO_FILTER_SUPPORT = 0x0401


# IP parameter flags. Ref: ETG.1000.6 §5.7 (Set IP Parameter request).
F_MAC = 0x01
F_IP = 0x02
F_SUBNET = 0x04
F_GATEWAY = 0x08
F_DNS_IP = 0x10
F_DNS_NAME = 0x20


@dataclass(frozen=True, slots=True)
class EoeHeader:
    """The two EoE header words, decoded."""

    ftype: int
    port: int
    last: bool
    time_appended: bool
    time_request: bool
    fragment: int
    offset: int
    frame: int

    @property
    def result(self) -> int:
        """Word 2 as a control response's result code."""
        return self.fragment | (self.offset << 6) | (self.frame << 12)


def decode_header(data: bytes | memoryview) -> EoeHeader:
    """The EoE header at the start of ``data`` (at least 4 bytes)."""
    w1, w2 = EOE_HEADER.unpack_from(data)
    return EoeHeader(
        w1 & 0x0F,
        (w1 >> 4) & 0x0F,
        bool(w1 & 0x100),
        bool(w1 & 0x200),
        bool(w1 & 0x400),
        w2 & 0x3F,
        (w2 >> 6) & 0x3F,
        (w2 >> 12) & 0x0F,
    )


def fragment_header(
    *,
    fragment: int,
    offset: int,
    frame: int,
    last: bool,
    port: int = 0,
    time_appended: bool = False,
    time_request: bool = False,
) -> bytes:
    """The header of a data fragment (type 0)."""
    w1 = (
        EoeType.FRAGMENT
        | (port & 0x0F) << 4
        | (0x100 if last else 0)
        | (0x200 if time_appended else 0)
        | (0x400 if time_request else 0)
    )
    w2 = (fragment & 0x3F) | (offset & 0x3F) << 6 | (frame & 0x0F) << 12
    return EOE_HEADER.pack(w1, w2)


def control_header(ftype: int, result: int = 0, port: int = 0) -> bytes:
    """The header of a control request or response: last fragment set, word 2 the result."""
    return EOE_HEADER.pack((ftype & 0x0F) | (port & 0x0F) << 4 | 0x100, result & 0xFFFF)


def ip_bytes(octets: bytes) -> bytes:
    """An IPv4 address (network order) as EoE carries it: octet-reversed."""
    return bytes(reversed(octets))


@dataclass(frozen=True, slots=True)
class IpParams:
    """The fields of a Set/Get IP Parameter block; None: not included. Addresses in
    network order (``bytes([10, 77, 0, 2])``)."""

    mac: bytes | None = None
    ip: bytes | None = None
    subnet: bytes | None = None
    gateway: bytes | None = None
    dns_ip: bytes | None = None
    dns_name: bytes | None = None


_FIELDS = (
    (F_MAC, "mac", 6),
    (F_IP, "ip", 4),
    (F_SUBNET, "subnet", 4),
    (F_GATEWAY, "gateway", 4),
    (F_DNS_IP, "dns_ip", 4),
    (F_DNS_NAME, "dns_name", DNS_NAME_LEN),
)


def decode_ip_params(data: bytes) -> IpParams | None:
    """The IP parameter block after the EoE header; None if it is shorter than its flags
    say. Ref: ETG.1000.6 §5.7 (Set IP Parameter request)."""
    if len(data) < 4:
        return None
    flags = struct.unpack_from("<I", data)[0]
    pos = 4
    out: dict[str, bytes] = {}
    for bit, name, size in _FIELDS:
        if flags & bit:
            if pos + size > len(data):
                return None
            raw = data[pos : pos + size]
            out[name] = raw if name in ("mac", "dns_name") else ip_bytes(raw)
            pos += size
    return IpParams(**out)


def encode_ip_params(p: IpParams) -> bytes:
    """The IP parameter block of a Get IP Parameter response: flags, included fields."""
    flags = 0
    body = b""
    for bit, name, size in _FIELDS:
        v = getattr(p, name)
        if v is None:
            continue
        flags |= bit
        if name == "dns_name":
            body += bytes(v[:size]).ljust(size, b"\x00")
        elif name == "mac":
            body += bytes(v[:size])
        else:
            body += ip_bytes(v)
    return struct.pack("<I", flags) + body
