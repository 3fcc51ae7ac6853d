"""Ethernet, VLAN and EtherCAT frame headers, decoded in place.

Ref: ETG.1000.4 §5.3 (EtherCAT frame structure); IEEE 802.1Q (VLAN tag);
TMC8460 §5.17 (DL Control 0x0100 bit 0: SOURCE_MAC[1] is set on every frame).
"""

from __future__ import annotations

import struct

ETHERTYPE_ECAT = 0x88A4
ETHERTYPE_VLAN = 0x8100
ETH_HEADER_LEN = 14
VLAN_TAG_LEN = 4
ECAT_HEADER_LEN = 2
#: EtherCAT header type 1: the frame carries EtherCAT datagrams (DLPDUs).
ECAT_TYPE_DLPDU = 1

_U16BE = struct.Struct(">H")
U16 = struct.Struct("<H")


def ecat_offset(buf: bytearray | memoryview, n: int, ethernet: bool) -> int:
    """Offset of the EtherCAT header in a received frame, or -1 if it is not EtherCAT.

    Ref: ETG.1000.4 §5.3.1, IEEE 802.1Q.
    """
    if not ethernet:
        return 0 if n >= ECAT_HEADER_LEN else -1
    if n < ETH_HEADER_LEN + ECAT_HEADER_LEN:
        return -1
    etype = (buf[12] << 8) | buf[13]
    if etype == ETHERTYPE_ECAT:
        return ETH_HEADER_LEN
    if (
        etype == ETHERTYPE_VLAN
        and n >= ETH_HEADER_LEN + VLAN_TAG_LEN + ECAT_HEADER_LEN
        and ((buf[16] << 8) | buf[17]) == ETHERTYPE_ECAT
    ):
        return ETH_HEADER_LEN + VLAN_TAG_LEN
    return -1


def mark_processed(buf: bytearray | memoryview) -> None:
    """Set bit 1 of the first source-MAC octet (locally administered), as every ESC does.

    Ref: TMC8460 §5.17 Table 28, DL Control bit 0 note.
    """
    buf[6] |= 0x02
