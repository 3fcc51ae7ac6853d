"""ESC register details of TMC8460 §5, exact bytes through ECAT frames and the PDI: the MII
management interface (§5.46), the DC cyclic unit control and SYNC/LATCH details (§5.50),
ESC configuration from the EEPROM (§5.19, §5.26), alias, SM length 1, PDI EEPROM commands
and the parameter RAM (§5.10, §5.45, §5.47, §5.49). Decisions R5-n in docs/decisions.md."""

from __future__ import annotations

import struct

from ecatsim.esc.pdi import Pdi
from tests.support.tinymaster import TinyMaster, segment_of

# ================================================================ MII management (§5.46)


def mii(t: TinyMaster) -> bytes:
    """0x0510:0x051B as ECAT reads it."""
    return t.aprd(0, 0x0510, 12).data


def test_mii_reset_values() -> None:
    """Control/status: PDI control possible (bit 1), port 0's PHY address 0 (PHY_OFFSET low),
    MI link detection off, idle; everything else 0. Ref: §5.46 Tables 67-73."""
    seg, _ = segment_of(1)
    t = TinyMaster(seg)
    assert mii(t) == bytes.fromhex("0200 00 00 0000 00 00 00000000")


def test_mii_read_returns_the_phy_registers() -> None:
    """A read command completes at once (busy and command bits clear) with the PHY's
    register in 0x0514: the IP101GA identifier, basic status with the link of port 0
    (the master's side) and without one on port 1 (no slave behind). Ref: Tables 67-70."""
    seg, _ = segment_of(1)
    t = TinyMaster(seg)

    def read(phy: int, reg: int) -> bytes:
        t.apwr(0, 0x0512, bytes([phy, reg]))
        t.apwr(0, 0x0511, b"\x01")  # command 01: read
        return t.aprd(0, 0x0510, 6).data

    assert read(0, 2) == bytes.fromhex("0200 00 02 4302")
    assert read(0, 3) == bytes.fromhex("0200 00 03 540c")
    assert read(0, 0) == bytes.fromhex("0200 00 00 0031")
    assert read(0, 1) == bytes.fromhex("0200 00 01 6d78")  # link, autonegotiation complete
    assert read(1, 1) == bytes.fromhex("0200 01 01 4978")  # port 1: no link
    assert read(0, 5) == bytes.fromhex("0200 00 05 e141")  # link partner ability
    # no PHY at address 2: read error (bit 13), MDIO's pull-up reads all ones
    assert read(2, 1) == bytes.fromhex("0220 02 01 ffff")
    # writing the register clears the read error; command 00 clears the command error
    t.apwr(0, 0x0511, b"\x00")
    assert t.aprd(0, 0x0510, 2).data == b"\x02\x00"


def test_mii_write_needs_write_enable_in_the_same_frame() -> None:
    """A write command without write enable is a command error (bit 14); write enable
    (bit 0) with the command is stored in the PHY; write enable written in an earlier frame
    has cleared itself at this frame's SOF. Read-only PHY registers keep their value; a
    control register reset (0.15) restores the PHY's defaults. Ref: Table 67 note *."""
    seg, _ = segment_of(1)
    t = TinyMaster(seg)
    t.apwr(0, 0x0512, b"\x00\x04\x61\x00")  # PHY 0, register 4 (advertisement) = 0x0061
    t.apwr(0, 0x0511, b"\x02")
    assert t.aprd(0, 0x0510, 2).data == b"\x02\x40"  # command error, nothing written
    t.apwr(0, 0x0510, b"\x01\x02")  # write enable + write command
    assert t.aprd(0, 0x0510, 2).data == b"\x02\x00"  # done, error cleared, WE self-cleared
    t.apwr(0, 0x0514, b"\x00\x00")
    t.apwr(0, 0x0511, b"\x01")
    assert t.aprd(0, 0x0514, 2).data == b"\x61\x00"
    t.apwr(0, 0x0510, b"\x01")  # write enable alone ...
    assert t.aprd(0, 0x0510, 1).data == b"\x02"  # ... cleared at the next frame's SOF
    t.apwr(0, 0x0514, b"\xe1\x01")
    t.apwr(0, 0x0511, b"\x02")
    assert t.aprd(0, 0x0510, 2).data == b"\x02\x40"
    # the identifier is read-only
    t.apwr(0, 0x0512, b"\x00\x02\x34\x12")
    t.apwr(0, 0x0510, b"\x01\x02")
    t.apwr(0, 0x0511, b"\x01")
    assert t.aprd(0, 0x0514, 2).data == b"\x43\x02"
    # software reset: register 4 back to 0x01E1, register 0 to 0x3100
    t.apwr(0, 0x0512, b"\x00\x00\x00\x80")
    t.apwr(0, 0x0510, b"\x01\x02")
    t.apwr(0, 0x0512, b"\x00\x04")
    t.apwr(0, 0x0511, b"\x01")
    assert t.aprd(0, 0x0514, 2).data == b"\xe1\x01"
    t.apwr(0, 0x0511, b"\x03")  # reserved command
    assert t.aprd(0, 0x0510, 2).data == b"\x02\x40"


def test_mii_port_address_selection() -> None:
    """0x0512.7 = 1 shows the PHY address of the port 0x0512[4:0] selects in 0x0510[7:3].
    Ref: Table 68 bit 7."""
    seg, _ = segment_of(1)
    t = TinyMaster(seg)
    t.apwr(0, 0x0512, b"\x81")
    assert t.aprd(0, 0x0510, 3).data == b"\x0a\x00\x81"
    t.apwr(0, 0x0512, b"\x01")
    assert t.aprd(0, 0x0510, 3).data == b"\x02\x00\x01"


def test_mii_ownership_between_ecat_and_pdi() -> None:
    """The PDI takes the interface with 0x0517.0 (EEPROM loaded, ECAT not claiming it);
    then only the PDI writes commands and PHY registers, write enable reads 1, and ECAT's
    writes do nothing. ECAT's 0x0517.1 takes it back; 0x0516.0 = 1 keeps the PDI out.
    Writes of the port status registers clear bits 3/5 (they read 0: no MI link
    detection). Ref: §5.46 Tables 67, 71-73."""
    seg, _ = segment_of(1)
    t = TinyMaster(seg)
    pdi = Pdi(seg.escs[0])
    assert pdi.write(0x0511, b"\x01")  # not the owner: ignored
    assert pdi.read(0x0510, 2) == b"\x02\x00"
    pdi.write(0x0517, b"\x01")
    assert t.aprd(0, 0x0516, 2).data == b"\x00\x01"
    assert t.aprd(0, 0x0510, 2).data == b"\x03\x00"  # write enable always 1
    t.apwr(0, 0x0512, b"\x00\x03")  # ECAT: no access
    t.apwr(0, 0x0511, b"\x01")
    t.apwr(0, 0x0516, b"\x01")  # not while the PDI has access
    assert t.aprd(0, 0x0510, 7).data == bytes.fromhex("0300 00 00 0000 00")
    pdi.write(0x0512, b"\x00\x04\x21\x00")
    pdi.write(0x0511, b"\x02")  # write: no write enable needed
    pdi.write(0x0514, b"\x00\x00")
    pdi.write(0x0511, b"\x01")
    assert pdi.read(0x0510, 6) == bytes.fromhex("0300 00 04 2100")
    t.apwr(0, 0x0517, b"\x02")  # force: ECAT has access again
    assert t.aprd(0, 0x0510, 8).data == bytes.fromhex("0200 00 04 2100 00 02")
    pdi.write(0x0517, b"\x01")  # refused while 0x0517.1 = 1
    assert pdi.read(0x0517, 1) == b"\x02"
    t.apwr(0, 0x0517, b"\x00")
    t.apwr(0, 0x0516, b"\x01")  # ECAT claims exclusive access
    pdi.write(0x0517, b"\x01")
    assert pdi.read(0x0516, 2) == b"\x01\x00"
    t.apwr(0, 0x0518, b"\xff\xff\xff\xff")
    assert t.aprd(0, 0x0518, 4).data == bytes(4)
