"""AL state machine through the firmware, the SII EEPROM command machine, the watchdog
and the 'RES' reset. Ref: ETG.1000.6 §6.4; TMC8460 §5.15, §5.20-5.22, §5.39-5.45."""

from __future__ import annotations

import struct

from ecatsim.esc.pdi import Pdi
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster, segment_of


def al(m: TinyMaster, pos: int = 0) -> tuple[int, int]:
    st = struct.unpack("<H", m.aprd(pos, 0x0130, 2).data)[0]
    code = struct.unpack("<H", m.aprd(pos, 0x0134, 2).data)[0]
    return st, code


def request(m: TinyMaster, state: int, pos: int = 0) -> None:
    m.apwr(pos, 0x0120, struct.pack("<H", state))


def mailbox_sms(m: TinyMaster, pos: int = 0, rx_len: int = 128, tx_len: int = 128) -> None:
    m.apwr(pos, 0x0800, struct.pack("<HHBBBB", 0x1000, rx_len, 0x26, 0, 1, 0))
    m.apwr(pos, 0x0808, struct.pack("<HHBBBB", 0x1080, tx_len, 0x22, 0, 1, 0))


def pd_sms(m: TinyMaster, pos: int = 0, out_len: int = 12, in_len: int = 17) -> None:
    m.apwr(pos, 0x0810, struct.pack("<HHBBBB", 0x1100, out_len, 0x64, 0, 1, 0))
    m.apwr(pos, 0x0818, struct.pack("<HHBBBB", 0x1200, in_len, 0x20, 0, 1, 0))


def test_init_to_preop_needs_mailbox_sms() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    assert al(m) == (0x01, 0)
    request(m, 0x02)
    assert al(m) == (0x11, 0x0016)  # invalid mailbox configuration
    request(m, 0x02)
    assert al(m) == (0x11, 0x0016)  # not acknowledged: stays in error
    mailbox_sms(m)
    request(m, 0x12)  # PREOP + error ack
    assert al(m) == (0x02, 0)


def test_invalid_and_unknown_requests() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    request(m, 0x08)
    assert al(m) == (0x11, 0x0011)
    request(m, 0x01)  # INIT clears the error
    assert al(m) == (0x01, 0)
    request(m, 0x05)
    assert al(m) == (0x11, 0x0012)
    request(m, 0x11)
    request(m, 0x03)  # BOOT without the bootstrap mailbox SMs
    assert al(m) == (0x11, 0x0015)
    mailbox_sms(m)
    request(m, 0x13)  # BOOT + ack: the bootstrap mailbox is configured now
    assert al(m) == (0x03, 0)
    request(m, 0x02)  # BOOT -> PREOP is not a transition
    assert al(m) == (0x13, 0x0011)
    request(m, 0x01)
    assert al(m) == (0x01, 0)


def test_full_walk_to_op_and_back() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    mailbox_sms(m)
    request(m, 0x02)
    assert al(m) == (0x02, 0)
    pd_sms(m, out_len=10)
    request(m, 0x04)
    assert al(m) == (0x12, 0x001D)  # wrong output size
    m.apwr(0, 0x0816, b"\x00")
    m.apwr(0, 0x0812, struct.pack("<H", 12))
    m.apwr(0, 0x0816, b"\x01")
    m.apwr(0, 0x081E, b"\x00")
    m.apwr(0, 0x081A, struct.pack("<H", 16))
    m.apwr(0, 0x081E, b"\x01")
    request(m, 0x14)
    assert al(m) == (0x12, 0x001E)  # wrong input size
    m.apwr(0, 0x081E, b"\x00")
    m.apwr(0, 0x081A, struct.pack("<H", 17))
    m.apwr(0, 0x081E, b"\x01")
    request(m, 0x14)
    assert al(m) == (0x04, 0)
    request(m, 0x08)
    assert al(m) == (0x04, 0)  # OP waits for the first outputs (decision F5)
    m.apwr(0, 0x1100, bytes(12))
    assert al(m) == (0x08, 0)
    request(m, 0x02)
    assert al(m) == (0x02, 0)
    request(m, 0x01)
    assert al(m) == (0x01, 0)


def to_safeop(m: TinyMaster) -> None:
    mailbox_sms(m)
    request(m, 0x02)
    pd_sms(m)
    request(m, 0x04)
    assert al(m) == (0x04, 0)


def test_safeop_to_op_waits_for_the_first_outputs() -> None:
    """SAFEOP -> OP completes when SM2 is first written, however long the master takes;
    outputs written in SAFEOP before the request count. ETG.1000.6 §6.4.1.2 (SO: "start
    output update"); decision F5."""
    seg, clock = segment_of(1)
    m = TinyMaster(seg, clock)
    to_safeop(m)
    request(m, 0x08)
    assert al(m) == (0x04, 0)
    clock.advance(5_000_000_000)
    assert m.aprd(0, 0x1200, 17).wkc == 1  # the master reads inputs: the firmware runs
    assert al(m) == (0x04, 0)
    m.apwr(0, 0x1100, bytes(12))
    assert al(m) == (0x08, 0)
    request(m, 0x04)  # back to SAFEOP: the outputs are forgotten
    assert al(m) == (0x04, 0)
    request(m, 0x08)
    assert al(m) == (0x04, 0)
    request(m, 0x04)  # a new request replaces the waiting one
    m.apwr(0, 0x1100, bytes(12))
    assert al(m) == (0x04, 0)
    request(m, 0x08)  # outputs seen in SAFEOP: OP at once
    assert al(m) == (0x08, 0)


def test_safeop_to_op_without_outputs_is_refused_with_001b() -> None:
    seg, clock = segment_of(1)
    m = TinyMaster(seg, clock)
    to_safeop(m)
    request(m, 0x08)
    clock.advance(8_999_000_000)
    m.aprd(0, 0x1200, 17)
    assert al(m) == (0x04, 0)
    clock.advance(1_000_000)  # 9 s: before the master's SafeopOpTimeout (10 s)
    m.aprd(0, 0x1200, 17)
    assert al(m) == (0x14, 0x001B)  # SAFEOP, error: sync manager watchdog
    m.apwr(0, 0x1100, bytes(12))
    request(m, 0x18)  # OP with the error acknowledged, outputs there
    assert al(m) == (0x08, 0)


def test_al_status_read_clears_ecat_event() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    request(m, 0x08)
    assert m.aprd(0, 0x0210, 2).data[0] & 0x08
    m.aprd(0, 0x0130, 2)
    assert m.aprd(0, 0x0210, 2).data[0] & 0x08 == 0


def test_device_emulation_copies_control_to_status() -> None:
    seg, _ = segment_of(1)
    esc = seg.escs[0]
    esc.mem[0x0141] |= 0x01  # device emulation (EEPROM word 0 bit 8)
    m = TinyMaster(seg)
    request(m, 0x18)  # OP + ack: copied without the ack bit
    assert struct.unpack("<H", m.aprd(0, 0x0130, 2).data)[0] == 0x08
    assert Pdi(esc).al_event() & 0x01 == 0  # no AL control event in emulation


def eeprom_cmd(m: TinyMaster, cmd: int, addr: int, pos: int = 0) -> int:
    m.apwr(pos, 0x0502, struct.pack("<HI", cmd, addr))
    return int(struct.unpack("<H", m.aprd(pos, 0x0502, 2).data)[0])


def test_eeprom_read_identity_words() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    st = eeprom_cmd(m, 0x0100, 0x0008)
    assert st & 0x8000 == 0 and st & 0x6000 == 0
    assert m.aprd(0, 0x0508, 4).data == struct.pack("<I", 0x286)
    eeprom_cmd(m, 0x0100, 0x000A)
    assert m.aprd(0, 0x0508, 4).data == struct.pack("<I", 8670)


def test_eeprom_write_needs_enable_and_persists() -> None:
    seg, _ = segment_of(1)
    saved: list[int] = []
    seg.schedule.persist = saved.append
    m = TinyMaster(seg)
    m.apwr(0, 0x0508, b"\x34\x12")
    st = eeprom_cmd(m, 0x0200, 0x0040)
    assert st & 0x4000  # write without enable
    assert saved == []
    eeprom_cmd(m, 0x0000, 0)  # NOP clears the error bits
    m.apwr(0, 0x0508, b"\x34\x12")
    st = eeprom_cmd(m, 0x0201, 0x0040)
    assert st & 0x6000 == 0
    assert saved == [0]
    eeprom_cmd(m, 0x0100, 0x0040)
    assert m.aprd(0, 0x0508, 2).data == b"\x34\x12"


def test_eeprom_invalid_command_and_pdi_ownership() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    st = eeprom_cmd(m, 0x0300, 0)
    assert st & 0x2000
    eeprom_cmd(m, 0x0000, 0)
    m.apwr(0, 0x0500, b"\x01")  # offer to PDI: ECAT commands ignored
    eeprom_cmd(m, 0x0100, 0x0008)
    assert m.aprd(0, 0x0508, 4).data != struct.pack("<I", 0x286)
    m.apwr(0, 0x0500, b"\x02")  # force ECAT
    m.apwr(0, 0x0500, b"\x00")
    eeprom_cmd(m, 0x0100, 0x0008)
    assert m.aprd(0, 0x0508, 4).data == struct.pack("<I", 0x286)


def test_eeprom_reload_keeps_the_alias() -> None:
    """The alias is taken from the EEPROM only at the first load after power-on or reset
    (TMC8460 §5.10 Table 21 note); a reload keeps the value the PDI wrote."""
    seg, _ = segment_of(1, alias=0x0042)
    m = TinyMaster(seg)
    assert m.aprd(0, 0x0012, 2).data == b"\x42\x00"
    Pdi(seg.escs[0]).write(0x0012, b"\x99\x00")
    assert m.aprd(0, 0x0012, 2).data == b"\x99\x00"
    eeprom_cmd(m, 0x0400, 0)
    assert m.aprd(0, 0x0012, 2).data == b"\x99\x00"
    seg.escs[0].hardware_reset()
    assert m.aprd(0, 0x0012, 2).data == b"\x42\x00"


def test_watchdog_expiry_leaves_op_with_001b() -> None:
    seg, clock = segment_of(1)
    m = TinyMaster(seg)
    mailbox_sms(m)
    request(m, 0x02)
    pd_sms(m)
    request(m, 0x04)
    m.apwr(0, 0x1100, bytes(12))  # outputs: triggers the watchdog (SM2 control bit 6)
    request(m, 0x08)
    assert al(m) == (0x08, 0)
    assert m.aprd(0, 0x0440, 2).data[0] & 0x01 == 1
    clock.advance(99_000_000)
    seg.service()
    assert al(m) == (0x08, 0)
    clock.advance(2_000_000)
    seg.service()
    assert al(m) == (0x14, 0x001B)
    assert m.aprd(0, 0x0440, 1).data[0] & 0x01 == 0
    assert m.aprd(0, 0x0442, 1).data == b"\x01"


def test_res_sequence_resets_the_esc() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    m.apwr(0, 0x0010, b"\x00\x10")

    def write_and_read(c: bytes) -> bytes:
        rs = m.frame(
            [
                dg.build(dg.Cmd.APWR, 0, 0x0040, c, more=True),
                dg.build(dg.Cmd.APRD, 0, 0x0040, b"\x00"),
            ]
        )
        assert rs is not None
        return rs[1].data

    assert write_and_read(b"R") == b"\x01"
    assert write_and_read(b"E") == b"\x02"
    assert write_and_read(b"X") == b"\x00"
    assert write_and_read(b"R") == b"\x01"
    m.aprd(0, 0x0000, 1)  # another frame in between breaks the sequence
    assert write_and_read(b"E") == b"\x00"
    for c in b"RES":
        m.apwr(0, 0x0040, bytes([c]))
    assert m.aprd(0, 0x0010, 2).data == b"\x00\x00"  # station address back to reset value
    assert al(m) == (0x01, 0)


def test_pdi_res_sequence_resets_the_esc() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    m.apwr(0, 0x0010, b"\x00\x10")
    pdi = Pdi(seg.escs[0])
    pdi.write(0x0041, b"R")
    assert pdi.u8(0x0041) == 0x01
    pdi.write(0x0041, b"X")
    assert pdi.u8(0x0041) == 0x00
    for c in b"RES":
        pdi.write(0x0041, bytes([c]))
    assert m.aprd(0, 0x0010, 2).data == b"\x00\x00"
