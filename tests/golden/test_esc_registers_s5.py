"""ESC register details of TMC8460 §5, exact bytes through ECAT frames and the PDI: the MII
management interface (§5.46), the DC cyclic unit control and SYNC/LATCH details (§5.50),
ESC configuration from the EEPROM (§5.19, §5.26), alias, SM length 1, PDI EEPROM commands
and the parameter RAM (§5.10, §5.45, §5.47, §5.49). Decisions R5-n in docs/decisions.md."""

from __future__ import annotations

import struct

from ecatsim.clock import ManualClock
from ecatsim.esc.core import Esc
from ecatsim.esc.pdi import Pdi
from ecatsim.ethercat.segment import Segment
from ecatsim.sii.crc import crc8
from ecatsim.wire import datagram as dg
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


# ================================================================ DC units (§5.50)

MS = 1_000_000
Q = struct.Struct("<Q")


def u64(t: TinyMaster, ado: int) -> int:
    return int(Q.unpack(t.aprd(0, ado, 8).data)[0])


def test_cyclic_unit_control_gives_the_sync_unit_to_the_pdi() -> None:
    """0x0980.0 = 1: the SYNC out unit's registers (0x0981, 0x0990, 0x09A0, 0x09A4) are
    written by the PDI only; back at 0 by ECAT only. Ref: Table 104, notes of Tables 105,
    110, 112, 113."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    pdi = Pdi(esc)
    now = esc.dc.system_time(clock.t)
    t.apwr(0, 0x0980, b"\x01")
    assert t.aprd(0, 0x0980, 1).data == b"\x01"
    t.apwr(0, 0x0990, Q.pack(now + 2 * MS))
    t.apwr(0, 0x09A0, struct.pack("<II", MS, 300))
    t.apwr(0, 0x0981, b"\x03")
    # all ignored (0x0982: the SII's pulse length, 1 us)
    assert t.aprd(0, 0x0980, 0x30).data == b"\x01\x00\x64" + bytes(0x2D)
    pdi.access_time(clock.t)
    assert pdi.write(0x0990, Q.pack(now + 2 * MS))
    pdi.write(0x09A0, struct.pack("<II", MS, 300))
    pdi.write(0x0981, b"\x03")
    assert t.aprd(0, 0x0981, 4).data == b"\x03\x64\x00\x01"  # pulse 1 us, SYNC0 pending
    assert esc.dc.sync0_deadline() == clock.t + 2 * MS
    assert t.aprd(0, 0x0990, 0x18).data == Q.pack(now + 2 * MS) + bytes(8) + struct.pack(
        "<II", MS, 300
    )
    t.apwr(0, 0x0980, b"\x00")  # ECAT again: the PDI's writes are ignored
    pdi.write(0x0981, b"\x00")
    assert t.aprd(0, 0x0981, 1).data == b"\x03"
    t.apwr(0, 0x0981, b"\x00")
    assert t.aprd(0, 0x0981, 4).data == b"\x00\x64\x00\x00"
    assert esc.dc.sync0_deadline() is None


def test_pdi_controlled_latch_unit_raises_the_al_event() -> None:
    """0x0980.4 = 1: LATCH0 is the PDI's: its control register is written by the PDI,
    its edges raise AL event 0x0220.1 (not ECAT's 0x0210.0), and the PDI's read of the
    time clears the event flag and the AL event; an ECAT read clears nothing. LATCH1 stays
    ECAT's. Ref: Table 104 bits 4/5, Tables 45, 46, 114-121."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    pdi = Pdi(esc)
    t.apwr(0, 0x0980, b"\x10")
    t.apwr(0, 0x09A8, b"\x03\x03")  # LATCH0 control: the PDI's; LATCH1: single events
    assert t.aprd(0, 0x09A8, 2).data == b"\x00\x03"
    pdi.write(0x09A8, b"\x01\x00")  # LATCH0 positive edge: single event
    assert pdi.read(0x09A8, 2) == b"\x01\x03"
    clock.t += 1000
    esc.latch_input(0, True, clock.t)
    pos = esc.dc.system_time(clock.t)
    assert pdi.al_event() & 0x02 and not esc.mem[0x0210] & 0x01
    assert t.aprd(0, 0x09AE, 2).data == b"\x05\x00"
    assert u64(t, 0x09B0) == pos
    assert t.aprd(0, 0x09AE, 1).data == b"\x05"  # an ECAT read clears nothing
    assert Q.unpack(pdi.read(0x09B0, 8))[0] == pos
    assert pdi.read(0x09AE, 1) == b"\x04" and not pdi.al_event() & 0x02
    esc.latch_input(1, True, clock.t + 500)  # LATCH1: ECAT's
    assert esc.mem[0x0210] & 0x01 and not pdi.al_event() & 0x02
    assert t.aprd(0, 0x09AF, 1).data == b"\x05"
    pdi.read(0x09C0, 8)  # the PDI's read of an ECAT unit clears nothing
    assert t.aprd(0, 0x09AF, 1).data == b"\x05"
    assert u64(t, 0x09C0) == esc.dc.system_time(clock.t + 500)
    assert t.aprd(0, 0x09AF, 1).data == b"\x04" and not esc.mem[0x0210] & 0x01


def test_latch0_works_while_sync0_drives_its_pin() -> None:
    """0x0151.2 = 1 (SYNC0 output) does not take LATCH0's input: concurrent SYNC outputs
    and LATCH inputs (Table 42 note *)."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    assert t.aprd(0, 0x0151, 1).data == b"\x0e"  # SYNC0 output, mapped to 0x0220.2
    esc.latch_input(0, True, clock.t + 100)
    esc.latch_input(0, False, clock.t + 900)
    assert u64(t, 0x09B0) == esc.dc.system_time(clock.t + 100)
    assert u64(t, 0x09B8) == esc.dc.system_time(clock.t + 900)
    assert t.aprd(0, 0x09AE, 1).data == b"\x00" and esc.mem[0x0210] & 0x01 == 0


def test_start_time_auto_activation_and_32_bit_extension() -> None:
    """0x0981.3: writing the start time activates the unit (0x0981.0 set); written as
    32 bits (0x0981.3 or .4) it is extended to 64 bits, here across a 2^32 boundary of the
    system time. Ref: Table 105 bits 3/4, Table 110 note."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    local = u64(t, 0x0910)
    t.apwr(0, 0x0920, Q.pack((7 << 32) - MS - local))  # system time 1 ms before 7 x 2^32
    now = esc.dc.system_time(clock.t)
    assert now == (7 << 32) - MS
    t.apwr(0, 0x09A0, struct.pack("<I", MS))
    t.apwr(0, 0x0981, b"\x0a")  # auto-activation, SYNC0
    assert t.aprd(0, 0x0981, 4).data == b"\x0a\x64\x00\x00"
    t.apwr(0, 0x0990, struct.pack("<I", 4 * MS))  # low 32 bits only
    assert t.aprd(0, 0x0981, 4).data == b"\x0b\x64\x00\x01"  # activated, SYNC0 pending
    assert u64(t, 0x0990) == (7 << 32) + 4 * MS  # extended upwards: 5 ms ahead
    assert esc.dc.sync0_deadline() == clock.t + 5 * MS
    t.apwr(0, 0x0990, Q.pack(123))  # not writable while active
    assert u64(t, 0x0990) == (7 << 32) + 4 * MS
    t.apwr(0, 0x0981, b"\x10")  # off; 32-bit start times extended (bit 4)
    t.apwr(0, 0x0990, struct.pack("<I", (-3 * MS) & 0xFFFFFFFF))
    assert u64(t, 0x0990) == (7 << 32) - 3 * MS  # 2 ms ago: below the boundary
    t.apwr(0, 0x0990, Q.pack(5 << 32))  # 8 bytes: taken as written
    assert u64(t, 0x0990) == 5 << 32
    t.apwr(0, 0x0981, b"\x00")
    t.apwr(0, 0x0990, struct.pack("<I", 2 * MS))  # no extension: the upper half stays
    assert u64(t, 0x0990) == (5 << 32) + 2 * MS


def test_start_time_plausibility_check() -> None:
    """A start time in the past is reached only after the 64-bit system time wraps: no
    pulse, the first one stays pending. With the plausibility check (0x0981.5) a start
    time outside the near future (0x0981.6: 2^31 ns, else 2^63 ns) starts the pulses at
    once (0x0990 = now) and sets 0x0984.2. Ref: Table 105 bits 5/6, Tables 107, 110."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    now = esc.dc.system_time(clock.t)
    t.apwr(0, 0x09A0, struct.pack("<I", MS))

    def activate(start: int, act: int) -> tuple[bytes, int | None]:
        """Activate and read 0x0984 in one frame (a due pulse fires before the next)."""
        t.apwr(0, 0x0981, b"\x00")
        t.apwr(0, 0x0990, Q.pack(start))
        r = t.frame(
            [
                dg.build(dg.Cmd.APWR, 0, 0x0981, bytes([act]), more=True),
                dg.build(dg.Cmd.APRD, 0, 0x0984, b"\x00"),
            ],
            service=False,
        )
        assert r is not None
        return r[1].data, esc.dc.sync0_deadline()

    assert activate(now - MS, 0x03) == (b"\x01", None)  # the past: no pulse
    assert activate(now + 3000 * MS, 0x03) == (b"\x01", clock.t + 3000 * MS)
    assert activate(now + 3000 * MS, 0x63) == (b"\x05", clock.t)  # beyond 2^31 ns: now
    assert u64(t, 0x0990) == now
    assert activate(now + 2000 * MS, 0x63) == (b"\x01", clock.t + 2000 * MS)
    assert activate(now - MS, 0x23) == (b"\x05", clock.t)  # the past is beyond 2^63 ns
    seg.service(clock.t)  # the first pulse fires at once; the next a cycle later
    assert t.aprd(0, 0x0984, 1).data == b"\x04" and t.aprd(0, 0x098E, 1).data == b"\x01"
    assert u64(t, 0x0990) == now + MS


def test_speed_counter_diff_follows_the_time_loop() -> None:
    """0x0932 shows the loop's rate correction as the speed counter difference: a slave
    whose clock runs 20 ppm slow settles near +5 x 20e-6 x (0x1000 + 2)^2 = +1679. Writing
    0x0930 resets it, 0x092C and the correction; 0x0934 resets 0x092C only.
    Ref: Tables 99-102."""
    from ecatsim.clock import ManualClock
    from ecatsim.ethercat.assembly import build_segment
    from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig

    clock = ManualClock(1_000_000_000)
    cfg = SegmentConfig(
        (
            SlaveConfig(device="echo", serial=1),
            SlaveConfig(device="echo", serial=2, dc_drift_ppm=-20.0),
        )
    )
    seg = build_segment(cfg, clock)
    t = TinyMaster(seg)
    t.apwr(0, 0x0010, b"\x00\x10")
    for _ in range(3000):
        clock.advance(MS)
        t.frame([dg.build(dg.Cmd.FRMW, 0x1000, 0x0910, bytes(8))])
    esc = seg.escs[1]
    scd = struct.unpack("<h", t.aprd(1, 0x0932, 2).data)[0]
    assert scd == int(esc.dc.rate_ppb * 5e-9 * 4098 * 4098)
    assert abs(scd - 1679) < 84  # within 1 ppm of the drift
    assert t.aprd(0, 0x0932, 2).data == b"\x00\x00"  # the reference: no correction
    t.apwr(1, 0x0934, b"\x04")
    assert t.aprd(1, 0x092C, 4).data == bytes(4) and t.aprd(1, 0x0932, 2).data != bytes(2)
    t.apwr(1, 0x0930, b"\x00\x10")
    assert t.aprd(1, 0x092C, 4).data == bytes(4) and t.aprd(1, 0x0932, 2).data == bytes(2)
    assert esc.dc.rate_ppb == 0.0


def test_sm_event_times() -> None:
    """SM latch events (0x0806+8n): bit 6 stamps 0x09F0 with the local time of the frame
    in which ECAT exchanged the buffer (its last byte), bit 7 stamps 0x09F8 when the PDI
    accesses the buffer start and 0x09FC when it exchanges the buffer. An SM without them
    stamps nothing. Ref: §5.49 Table 90, §5.50.6 Tables 122-124."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    pdi = Pdi(esc)
    U = struct.Struct("<I")

    def local(at: int) -> bytes:
        return U.pack(esc.dc.local_time(at) & 0xFFFFFFFF)

    t.apwr(0, 0x0810, struct.pack("<HHBBBB", 0x1100, 4, 0x64, 0, 0x01, 0))  # no events
    t.apwr(0, 0x0818, struct.pack("<HHBBBB", 0x1200, 4, 0x20, 0, 0xC1, 0))
    pdi.sm_deactivate(2, False)  # the firmware locked them in INIT ...
    pdi.sm_deactivate(3, False)
    seg.schedule.firmware = []  # ... and stays out of the way: the PDI accesses are the test's
    t.apwr(0, 0x1100, b"\x01\x02\x03\x04")
    pdi.access_time(clock.t)
    assert pdi.sm_read(2) == b"\x01\x02\x03\x04"
    assert t.aprd(0, 0x09F0, 16).data == bytes(16)
    t.apwr(0, 0x0816, b"\xc1")  # SM2: both latch events
    clock.advance(1000)
    t.apwr(0, 0x1100, b"\x05\x06")  # not the last byte: no exchange
    assert t.aprd(0, 0x09F0, 4).data == bytes(4)
    clock.advance(1000)
    t1 = clock.t
    t.apwr(0, 0x1102, b"\x07\x08")
    assert t.aprd(0, 0x09F0, 4).data == local(t1)
    clock.advance(1000)
    pdi.access_time(clock.t + 10)
    assert pdi.read(0x1100, 2) == b"\x05\x06"  # the start: a buffer start event only
    assert t.aprd(0, 0x09F8, 8).data == local(clock.t + 10) + bytes(4)
    pdi.access_time(clock.t + 20)
    assert pdi.read(0x1102, 2) == b"\x07\x08"  # the last byte: a buffer change event
    assert t.aprd(0, 0x09F8, 8).data == local(clock.t + 10) + local(clock.t + 20)
    clock.advance(1000)
    pdi.access_time(clock.t)  # SM3: the PDI writes, ECAT reads
    assert pdi.sm_write(3, b"\x11\x12\x13\x14")
    assert t.aprd(0, 0x09F8, 8).data == local(clock.t) * 2
    clock.advance(1000)
    t2 = clock.t
    assert t.aprd(0, 0x1200, 4).data == b"\x11\x12\x13\x14"
    assert t.aprd(0, 0x09F0, 4).data == local(t2)


# ================================================ ESC configuration from the EEPROM (§5.26)


def set_word0(esc: Esc, word0: int, alias: int | None = None) -> None:
    """Put another ESC configuration word 0 (and alias) into the EEPROM chip, checksum
    fixed (ETG.2010: CRC-8 of words 0-6 in word 7's low byte)."""
    img = esc.eeprom.image
    struct.pack_into("<H", img, 0, word0)
    if alias is not None:
        struct.pack_into("<H", img, 8, alias)
    img[14] = crc8(bytes(img[0:14]))


def reload(t: TinyMaster) -> int:
    t.apwr(0, 0x0502, b"\x00\x04")
    return int(struct.unpack("<H", t.aprd(0, 0x0502, 2).data)[0])


def test_sync_out_and_latch_in_units_follow_0x0141() -> None:
    """0x0141 is EEPROM word 0's high byte at every load: with bits 2/3 clear the SYNC out
    unit does not start (and a running one stops at the reload that clears the bit) and
    the latch in unit captures nothing. The shipped TMC8670 SII enables both (0x0C).
    Ref: §5.26 Table 38 bits 2/3."""
    seg, clock = segment_of(1)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    assert t.aprd(0, 0x0140, 2).data == b"\x05\x0c"
    now = esc.dc.system_time(clock.t)
    t.apwr(0, 0x09A0, struct.pack("<I", MS))
    t.apwr(0, 0x0990, Q.pack(now + 2 * MS))
    t.apwr(0, 0x0981, b"\x03")
    assert esc.dc.sync0_deadline() == clock.t + 2 * MS
    set_word0(esc, 0x0005)  # DC units off
    assert reload(t) == 0x0080
    assert t.aprd(0, 0x0140, 2).data == b"\x05\x00"
    assert esc.dc.sync0_deadline() is None and t.aprd(0, 0x0984, 1).data == b"\x00"
    clock.advance(5 * MS)
    seg.service()
    assert t.aprd(0, 0x098E, 1).data == b"\x00"  # no pulse
    t.apwr(0, 0x0981, b"\x00")
    t.apwr(0, 0x0990, Q.pack(now + 10 * MS))
    t.apwr(0, 0x0981, b"\x03")
    assert esc.dc.sync0_deadline() is None and t.aprd(0, 0x0984, 1).data == b"\x00"
    esc.latch_input(1, True, clock.t)
    assert t.aprd(0, 0x09AF, 1).data == b"\x00" and u64(t, 0x09C0) == 0
    set_word0(esc, 0x0805)  # the latch in unit only
    reload(t)
    esc.latch_input(1, True, clock.t + 100)
    assert t.aprd(0, 0x09AF, 1).data == b"\x04"
    assert u64(t, 0x09C0) == esc.dc.system_time(clock.t + 100)
    t.apwr(0, 0x0981, b"\x00")
    t.apwr(0, 0x0981, b"\x03")
    assert esc.dc.sync0_deadline() is None


def test_enhanced_link_detection_and_alias_at_the_first_load_only() -> None:
    """0x0110.2 reads 1 until the first EEPROM load, then word 0 bit 9 or bits 15:12
    (0x0141 bit 1 or bits 7:4); a reload changes 0x0141 but neither 0x0110.2 nor the
    alias 0x0012. The first good load after a checksum error is the first load.
    Ref: §5.19 Table 30 bit 2, §5.10 Table 21, §5.26 Table 38, Table 62 bits 11/12."""
    seg, _ = segment_of(1, device="tmc8460", alias=0x0123)
    t = TinyMaster(seg)
    esc = seg.escs[0]
    assert t.aprd(0, 0x0140, 2).data == b"\x00\x0f"  # device emulation, link, DC units
    assert t.aprd(0, 0x0110, 1).data[0] & 0x05 == 0x05  # loaded, enhanced link detection
    assert t.aprd(0, 0x0012, 2).data == b"\x23\x01"
    set_word0(esc, 0x0C00, alias=0x0456)  # no enhanced link detection
    assert reload(t) == 0x0080
    assert t.aprd(0, 0x0140, 2).data == b"\x00\x0c"  # device emulation off
    assert t.aprd(0, 0x0110, 1).data[0] & 0x04 == 0x04  # kept
    assert t.aprd(0, 0x0012, 2).data == b"\x23\x01"  # kept
    esc.eeprom.image[14] ^= 0xFF  # a checksum error at the next reset
    esc.pdi_emulation = True
    esc.hardware_reset()
    assert t.aprd(0, 0x0502, 2).data == b"\x80\x18"  # checksum error, not loaded
    assert t.aprd(0, 0x0140, 2).data == b"\x05\x0d"  # reset values; the emulation pin
    assert t.aprd(0, 0x0110, 1).data[0] & 0x05 == 0x04  # not loaded, enhanced link: 1
    assert t.aprd(0, 0x0012, 2).data == b"\x00\x00"
    set_word0(esc, 0x0C00)  # repaired: the next reload is the first good load
    assert reload(t) == 0x0080
    assert t.aprd(0, 0x0140, 2).data == b"\x00\x0c"
    assert t.aprd(0, 0x0110, 1).data[0] & 0x05 == 0x01  # loaded, enhanced link: 0
    assert t.aprd(0, 0x0012, 2).data == b"\x56\x04"


# ============================================= SM length 1, PDI EEPROM, parameter RAM


def bare(device: str = "echo") -> tuple[Segment, ManualClock, TinyMaster, Pdi]:
    """One slave whose firmware stays out of the way (the PDI accesses are the test's):
    it locked SM0-SM3 at its start (INIT); they are unlocked."""
    seg, clock = segment_of(1, device=device)
    pdi = Pdi(seg.escs[0])
    seg.schedule.firmware = []
    for n in range(4):
        pdi.sm_deactivate(n, False)
    return seg, clock, TinyMaster(seg), pdi


def test_sm_of_length_1_is_not_activated() -> None:
    """Length 1: the SM is not activated (no buffer, no status change, no SM event): its
    byte is plain memory for ECAT and the PDI, and a write of it only triggers the
    process-data watchdog (control bit 6). Length 2 activates. An FMMU over such a byte
    writes plain memory. Ref: §5.49 Table 87."""
    seg, _, t, pdi = bare()
    esc = seg.escs[0]
    t.apwr(0, 0x0810, struct.pack("<HHBBBB", 0x1100, 1, 0x64, 0, 1, 0))
    assert t.aprd(0, 0x0810, 8).data == bytes.fromhex("0011 0100 64 30 01 00")
    assert esc.sm_windows == () and not esc.sm[2].active
    assert t.aprd(0, 0x0440, 2).data == b"\x00\x00"
    assert t.apwr(0, 0x1100, b"\x5a").wkc == 1
    assert t.aprd(0, 0x0440, 2).data == b"\x01\x00"  # watchdog triggered
    assert t.aprd(0, 0x0815, 1).data == b"\x30" and pdi.al_event() & 0x0400 == 0
    assert pdi.read(0x1100, 1) == b"\x5a" and pdi.sm_read(2) is None
    assert pdi.write(0x1100, b"\xa5") and t.aprd(0, 0x1100, 1).data == b"\xa5"
    # an FMMU mapping logical 0x10000 onto the byte: written, not routed to the SM
    t.apwr(0, 0x0600, struct.pack("<IHBBHBBBxxx", 0x10000, 1, 0, 7, 0x1100, 0, 2, 1))
    assert esc.fmmus[0].sm is None
    r = t.frame([dg.build_logical(dg.Cmd.LWR, 0x10000, b"\x77")])
    assert r is not None and r[0].wkc == 1
    assert t.aprd(0, 0x1100, 1).data == b"\x77"
    # the watchdog bit off: no trigger; length 2: an SM
    esc.mem[0x0440] = 0
    t.apwr(0, 0x0816, b"\x00")
    t.apwr(0, 0x0814, b"\x24")
    t.apwr(0, 0x0816, b"\x01")
    t.apwr(0, 0x1100, b"\x01")
    assert t.aprd(0, 0x0440, 1).data == b"\x00"
    t.apwr(0, 0x0816, b"\x00")
    t.apwr(0, 0x0812, b"\x02\x00")
    t.apwr(0, 0x0816, b"\x01")
    assert esc.sm[2].active and esc.sm_windows[0][:2] == (0x1100, 0x1102)
    t.apwr(0, 0x1100, b"\x01\x02")
    assert t.aprd(0, 0x0815, 1).data == b"\x01" and pdi.sm_read(2) == b"\x01\x02"


def test_pdi_runs_eeprom_commands_when_it_owns_the_eeprom() -> None:
    """ECAT offers the EEPROM (0x0500.0), the PDI takes it (0x0501.0): the PDI writes
    address, data and commands and the same command machine runs (write enable always 1,
    no write enable needed); ECAT's writes of 0x0502-0x050F are ignored then. ECAT's
    0x0500.1 takes it back. The PDI cannot set the acknowledge error (bit 13: EEPROM
    emulation only). Ref: §5.45 Tables 59-64."""
    seg, _, t, pdi = bare()
    esc = seg.escs[0]
    pdi.write(0x0504, struct.pack("<I", 8))  # not the owner: ignored
    pdi.write(0x0502, b"\x00\x01")
    assert pdi.read(0x0500, 16) == bytes.fromhex("00 00 8000 00000000") + bytes(8)
    t.apwr(0, 0x0500, b"\x01")  # offered: the PDI has control
    assert t.aprd(0, 0x0502, 2).data == b"\x81\x00"  # write enable always 1
    pdi.write(0x0501, b"\x01")
    pdi.write(0x0504, struct.pack("<I", 0x0008))
    pdi.write(0x0502, b"\x00\x01")  # read: vendor id
    assert pdi.read(0x0502, 10) == bytes.fromhex("8100 08000000 86020000")
    t.apwr(0, 0x0504, struct.pack("<I", 0x000A))  # ECAT: ignored
    t.apwr(0, 0x0502, b"\x01\x01")
    assert t.aprd(0, 0x0502, 10).data == bytes.fromhex("8100 08000000 86020000")
    pdi.write(0x0504, struct.pack("<IH", 0x0030, 0xBEEF))
    pdi.write(0x0502, b"\x00\x02")  # write: no write enable needed
    assert esc.eeprom.image[0x60:0x62] == b"\xef\xbe" and 0 in seg.ctx.flush
    pdi.write(0x0508, b"\x00\x00")
    pdi.write(0x0502, b"\x00\x21")  # read, and bit 13: not the PDI's to write
    assert pdi.read(0x0502, 8) == bytes.fromhex("8100 30000000 efbe")
    pdi.write(0x0502, b"\x00\x07")  # reserved command: acknowledge error
    assert pdi.read(0x0502, 2) == b"\x81\x20"
    pdi.write(0x0502, b"\x00\x00")  # 000 clears the error bits
    assert pdi.read(0x0502, 2) == b"\x81\x00"
    t.apwr(0, 0x0500, b"\x02")  # force ECAT access
    assert t.aprd(0, 0x0500, 4).data == bytes.fromhex("02 00 8000")
    pdi.write(0x0502, b"\x00\x01")  # the PDI: ignored again
    assert pdi.read(0x0502, 2) == b"\x80\x00"
    t.apwr(0, 0x0502, struct.pack("<HI", 0x0100, 0x000A))
    assert t.aprd(0, 0x0508, 4).data == struct.pack("<I", 8670)


def test_parameter_ram_is_128_bytes() -> None:
    """0x0580:0x05FF is the ESC parameter RAM (Table 11): the 44 MFCIO configuration
    bytes 0x0580:0x05AB keep bits 4..0 (bits 7..5 reserved, Table 74), the rest is RAM
    for ECAT and the PDI; 0x0600 is the FMMUs'. Ref: §4 Table 11, §5.47."""
    _, _, t, pdi = bare()
    t.apwr(0, 0x0580, b"\xff" * 128)
    assert t.aprd(0, 0x0580, 128).data == b"\x1f" * 44 + b"\xff" * 84
    pdi.write(0x05AA, bytes(range(0xE0, 0xE6)))
    assert pdi.read(0x05A8, 8) == bytes.fromhex("1f1f 0001 e2e3e4e5")
    assert t.aprd(0, 0x05FE, 4).data == b"\xff\xff\x00\x00"
