"""Golden bytes: each datagram command against emulated TMC8460 slaves.

Data, WKC and ADP are asserted exactly. Ref: ETG.1000.4 Table 11/12; TMC8460 §5.
"""

from __future__ import annotations

import struct

from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster, segment_of

IDENTITY = bytes([0xD0, 0x60, 0x10, 0x00, 0x06, 0x06, 0x10, 0x0F, 0xCC, 0x01])


def test_aprd_identity_registers_and_adp() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    r = m.aprd(1, 0x0000, 10)
    assert r.data == IDENTITY
    assert r.wkc == 1
    assert r.adp == ((-1) & 0xFFFF) + 3 & 0xFFFF  # every slave increments ADP


def test_aprd_beyond_last_slave_gets_no_wkc() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    r = m.aprd(2, 0x0000, 2)
    assert r.wkc == 0
    assert r.data == b"\x00\x00"
    assert r.adp == 0  # -2 + 2


def test_brd_counts_slaves_and_ors_data() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    m.apwr(0, 0x0010, b"\x01\x00")
    m.apwr(2, 0x0010, b"\x04\x10")
    r = m.brd(0x0010, 2)
    assert r.wkc == 3
    assert r.data == b"\x05\x10"
    assert r.adp == 3


def test_bwr_and_fprd_station_address() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    assert m.apwr(0, 0x0010, b"\x00\x10").wkc == 1
    assert m.apwr(1, 0x0010, b"\x01\x10").wkc == 1
    r = m.fprd(0x1001, 0x0010, 2)
    assert (r.data, r.wkc, r.adp) == (b"\x01\x10", 1, 0x1001)
    assert m.fprd(0x1002, 0x0010, 2).wkc == 0
    r = m.bwr(0x0F80, b"\xaa\xbb")
    assert (r.wkc, r.adp) == (2, 2)
    assert m.fprd(0x1000, 0x0F80, 2).data == b"\xaa\xbb"


def test_fprw_reads_old_and_writes_new_wkc3() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    m.apwr(0, 0x0010, b"\x00\x10")
    m.fpwr(0x1000, 0x0F80, b"\x11\x22")
    r = m.one(dg.build(dg.Cmd.FPRW, 0x1000, 0x0F80, b"\x33\x44"))
    assert (r.data, r.wkc) == (b"\x11\x22", 3)
    assert m.fprd(0x1000, 0x0F80, 2).data == b"\x33\x44"


def test_aprw_on_read_only_register_still_counts() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    r = m.one(dg.build(dg.Cmd.APRW, 0, 0x0000, b"\x00\x00"))
    assert (r.data, r.wkc) == (b"\xd0\x60", 3)
    assert m.aprd(0, 0x0000, 1).data == b"\xd0"  # type register is read-only


def test_armw_reads_at_addressed_and_writes_at_others() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    m.apwr(1, 0x0F80, b"\x5a\x5a\x5a\x5a")
    r = m.one(dg.build(dg.Cmd.ARMW, (-1) & 0xFFFF, 0x0F80, b"\x00\x00\x00\x00"))
    assert r.data == b"\x5a\x5a\x5a\x5a"
    assert r.wkc == 3  # 1 read + 2 writes
    assert m.aprd(0, 0x0F80, 4).data == b"\x00\x00\x00\x00"  # written before the reader
    assert m.aprd(2, 0x0F80, 4).data == b"\x5a\x5a\x5a\x5a"  # written after the reader


def test_frmw_reads_at_station_and_writes_at_others() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    m.apwr(0, 0x0010, b"\x00\x10")
    m.apwr(1, 0x0010, b"\x01\x10")
    m.apwr(0, 0x0F80, b"\x77\x00")
    r = m.one(dg.build(dg.Cmd.FRMW, 0x1000, 0x0F80, b"\x00\x00"))
    assert (r.data, r.wkc, r.adp) == (b"\x77\x00", 2, 0x1000)
    assert m.fprd(0x1001, 0x0F80, 2).data == b"\x77\x00"


def test_alias_addressing_needs_dl_control_bit24() -> None:
    seg, _ = segment_of(1, alias=0x2345)
    m = TinyMaster(seg)
    assert m.fprd(0x2345, 0x0012, 2).wkc == 0
    m.apwr(0, 0x0103, b"\x01")
    r = m.fprd(0x2345, 0x0012, 2)
    assert (r.data, r.wkc) == (b"\x45\x23", 1)


def test_nop_and_unknown_commands_are_untouched() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    r = m.one(dg.build(dg.Cmd.NOP, 0x1234, 0x0000, b"\x01\x02"))
    assert (r.data, r.wkc, r.adp) == (b"\x01\x02", 0, 0x1234)
    r = m.one(dg.build(15, 0, 0x0000, b"\x01\x02"))
    assert (r.data, r.wkc) == (b"\x01\x02", 0)


def test_more_follows_chain_is_processed_in_order() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    rs = m.frame(
        [
            dg.build(dg.Cmd.APWR, 0, 0x0F80, b"\x01", idx=1, more=True),
            dg.build(dg.Cmd.APRD, 0, 0x0F80, b"\x00", idx=2, more=True),
            dg.build(dg.Cmd.BRD, 0, 0x0000, b"\x00", idx=3),
        ]
    )
    assert rs is not None
    assert [(r.idx, r.data, r.wkc) for r in rs] == [
        (1, b"\x01", 1),
        (2, b"\x01", 1),
        (3, b"\xd0", 1),
    ]


def test_truncated_datagram_is_counted_and_destroyed() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    good = dg.build(dg.Cmd.BRD, 0, 0, b"\x00\x00")
    bad = bytearray(dg.ethernet_frame([good]))
    bad[14] = (bad[14] & 0) | 0x40  # EtherCAT length 64 > frame
    off = 14
    assert seg.process(bad, off, len(bad)) is False
    assert m.aprd(0, 0x030C, 1).data == b"\x01"  # processing unit error at the first ESC
    assert m.aprd(1, 0x0308, 1).data == b"\x01"  # forwarded error behind it
    # the datagram length field running past the EtherCAT length
    frame = bytearray(dg.ethernet_frame([good]))
    struct.pack_into("<H", frame, 14 + 2 + 6, 0x0400)
    assert seg.process(frame, off, len(frame)) is False
    assert m.aprd(0, 0x030C, 1).data == b"\x02"
    # writing the counter clears it
    m.apwr(0, 0x030C, b"\x00")
    assert m.aprd(0, 0x030C, 1).data == b"\x00"


def test_source_mac_bit_set_on_reply() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    m.brd(0, 1)
    assert m.last_frame[6] & 0x02


def test_dl_status_reflects_ports() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    assert m.aprd(0, 0x0110, 2).data == bytes([0x33, 0x5A])
    assert m.aprd(1, 0x0110, 2).data == bytes([0x33, 0x5A])
    assert m.aprd(2, 0x0110, 2).data == bytes([0x13, 0x56])


def test_closing_port1_hides_the_slaves_behind() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    m.apwr(0, 0x0101, b"\x0c")  # loop port 1: closed
    assert m.brd(0x0000, 1).wkc == 1
    m.apwr(0, 0x0101, b"\x00")
    assert m.brd(0x0000, 1).wkc == 3


def test_write_to_unavailable_register_is_ignored() -> None:
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    r = m.apwr(0, 0x0021, b"\x01")  # write register protection: not on the TMC8460-BI
    assert r.wkc == 1
    assert m.aprd(0, 0x0021, 1).data == b"\x00"


def test_pdram_inaccessible_when_eeprom_checksum_bad() -> None:
    seg, _ = segment_of(1)
    esc = seg.escs[0]
    esc.eeprom.image[14] ^= 0xFF
    esc.hardware_reset()
    m = TinyMaster(seg)
    assert m.apwr(0, 0x1000, b"\x01").wkc == 0
    st = struct.unpack("<H", m.aprd(0, 0x0502, 2).data)[0]
    assert st & 0x0800 and st & 0x1000
    assert m.aprd(0, 0x0110, 1).data[0] & 0x01 == 0


def test_irq_field_carries_masked_ecat_events() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    assert m.brd(0x0000, 1).irq == 0
    m.apwr(1, 0x0200, b"\x08\x00")  # slave 1: map the AL status event
    m.apwr(1, 0x0120, b"\x08\x00")  # invalid request: AL status changes (error)
    assert m.brd(0x0000, 1).irq == 0x0008
    m.aprd(1, 0x0130, 2)  # reading AL status clears the event
    assert m.brd(0x0000, 1).irq == 0


def test_circulating_bit_with_port0_closed() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    m.apwr(1, 0x0101, b"\x03")  # slave 1: loop port 0 closed
    r = m.brd(0x0000, 1)
    assert r.flags & dg.CIRCULATING
    assert m.frame([dg.build(dg.Cmd.BRD, 0, 0, b"\x00", circulating=True)]) is None
    m.apwr(1, 0x0101, b"\x00")
    r = m.brd(0x0000, 1)
    assert not r.flags & dg.CIRCULATING
    assert m.frame([dg.build(dg.Cmd.BRD, 0, 0, b"\x00", circulating=True)]) is not None


def test_link_fault_hides_slaves_and_counts_lost_link() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    esc1, esc2 = seg.escs[1], seg.escs[2]
    esc1.set_link(1, False)
    esc2.set_link(0, False)
    assert m.brd(0x0000, 1).wkc == 2
    assert m.aprd(1, 0x0110, 2).data == bytes([0x13, 0x56])  # port 1: no link, closed
    assert m.aprd(1, 0x0311, 1).data == b"\x01"  # lost link counter, port 1
    esc1.set_link(1, True)
    esc2.set_link(0, True)
    assert m.brd(0x0000, 1).wkc == 3
    assert m.aprd(1, 0x0110, 2).data == bytes([0x33, 0x5A])
    seg.escs[0].set_link(0, False)
    assert m.frame([dg.build(dg.Cmd.BRD, 0, 0, b"\x00")]) is None  # nothing answers
