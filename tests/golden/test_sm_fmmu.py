"""SyncManager (mailbox and 3-buffer) and FMMU semantics, ECAT and PDI faces.

Ref: TMC8460 §5.48 (FMMU), §5.49 (SyncManager); ETG.1000.4 §6.6, §6.7.
"""

from __future__ import annotations

import struct

from ecatsim.esc.pdi import Pdi
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import TinyMaster, segment_of


def sm_regs(start: int, length: int, control: int, activate: int = 1) -> bytes:
    return struct.pack("<HHBBBB", start, length, control, 0, activate, 0)


def fmmu_regs(lad: int, length: int, lsb: int, lstop: int, phys: int, psb: int, typ: int) -> bytes:
    return struct.pack("<IHBBHBBB3x", lad, length, lsb, lstop, phys, psb, typ, 1)


def setup(n: int = 1) -> tuple[TinyMaster, Pdi]:
    seg, _ = segment_of(n)
    m = TinyMaster(seg)
    # the firmware locks SMs it does not serve; unlock SM 4/5 style raw SMs for these tests
    return m, Pdi(seg.escs[0])


def test_mailbox_write_only_when_empty_read_only_when_full() -> None:
    m, pdi = setup()
    # SM4 as a write mailbox (ECAT -> PDI) at 0x1400, 8 bytes, PDI irq
    assert m.apwr(0, 0x0820, sm_regs(0x1400, 8, 0x26)).wkc == 1
    r = m.apwr(0, 0x1400, b"ABCDEFGH")
    assert r.wkc == 1
    st = m.aprd(0, 0x0825, 1).data[0]
    assert st & 0x08 and st & 0x01  # full, write interrupt
    assert pdi.al_event() & (0x0100 << 4)
    assert m.apwr(0, 0x1400, b"XXXXXXXX").wkc == 0  # full: refused
    assert m.aprd(0, 0x1400, 8).wkc == 0  # ECAT cannot read its own write mailbox
    assert pdi.sm_read(4) == b"ABCDEFGH"
    assert m.aprd(0, 0x0825, 1).data[0] & 0x08 == 0  # empty again
    assert pdi.sm_read(4) is None
    assert m.apwr(0, 0x1400, b"12345678").wkc == 1


def test_mailbox_read_direction() -> None:
    m, pdi = setup()
    m.apwr(0, 0x0828, sm_regs(0x1480, 8, 0x22))  # SM5: read mailbox (PDI -> ECAT)
    assert m.aprd(0, 0x1480, 8).wkc == 0  # empty: nothing to read
    assert pdi.sm_write(5, b"reply!!!") is True
    assert pdi.sm_write(5, b"again!!!") is False  # full
    r = m.aprd(0, 0x1480, 8)
    assert (r.data, r.wkc) == (b"reply!!!", 1)
    assert m.aprd(0, 0x1480, 8).wkc == 0


def test_sm_registers_writable_only_while_disabled() -> None:
    m, _ = setup()
    m.apwr(0, 0x0820, sm_regs(0x1400, 8, 0x26))
    m.apwr(0, 0x0820, struct.pack("<H", 0x1600))
    assert m.aprd(0, 0x0820, 2).data == b"\x00\x14"
    m.apwr(0, 0x0826, b"\x00")  # disable
    m.apwr(0, 0x0820, struct.pack("<H", 0x1600))
    assert m.aprd(0, 0x0820, 2).data == b"\x00\x16"


def test_three_buffer_exchange_and_status() -> None:
    m, pdi = setup()
    # SM4: buffered, ECAT writes (outputs), 4 bytes at 0x1800
    m.apwr(0, 0x0820, sm_regs(0x1800, 4, 0x64))
    assert m.aprd(0, 0x0825, 1).data[0] & 0x30 == 0x30  # no buffer written
    assert m.apwr(0, 0x1800, b"\x01\x02\x03\x04").wkc == 1
    assert m.aprd(0, 0x0825, 1).data[0] & 0x30 == 0x00  # buffer 1
    assert m.apwr(0, 0x1800, b"\x05\x06\x07\x08").wkc == 1
    assert m.aprd(0, 0x0825, 1).data[0] & 0x30 == 0x10  # buffer 2
    assert pdi.sm_read(4) == b"\x05\x06\x07\x08"  # latest complete buffer
    # writes never block in 3-buffer mode
    for i in range(5):
        assert m.apwr(0, 0x1800, bytes([i] * 4)).wkc == 1
    assert pdi.sm_read(4) == bytes([4] * 4)
    # a partial write does not exchange
    m.apwr(0, 0x1800, b"\xaa\xbb")
    assert pdi.sm_read(4) == bytes([4] * 4)


def test_three_buffer_inputs_reader_keeps_consistent_buffer() -> None:
    m, pdi = setup()
    m.apwr(0, 0x0820, sm_regs(0x1900, 2, 0x20))  # buffered, ECAT reads
    assert pdi.sm_write(4, b"\x11\x11")
    assert m.aprd(0, 0x1900, 2).data == b"\x11\x11"
    # ECAT opens the buffer (first byte), PDI writes twice, ECAT finishes the old buffer
    assert m.aprd(0, 0x1900, 1).data == b"\x11"
    assert pdi.sm_write(4, b"\x22\x22")
    assert pdi.sm_write(4, b"\x33\x33")
    assert m.aprd(0, 0x1901, 1).data == b"\x11"
    assert m.aprd(0, 0x1900, 2).data == b"\x33\x33"


def test_pdi_deactivate_locks_the_area() -> None:
    m, pdi = setup()
    m.apwr(0, 0x0820, sm_regs(0x1400, 8, 0x26))
    pdi.sm_deactivate(4, True)
    assert m.aprd(0, 0x0827, 1).data == b"\x01"
    assert m.apwr(0, 0x1400, b"ABCDEFGH").wkc == 0
    pdi.sm_deactivate(4, False)
    assert m.apwr(0, 0x1400, b"ABCDEFGH").wkc == 1


def test_fmmu_byte_mapping_lrw_wkc() -> None:
    m, _ = setup()
    m.apwr(0, 0x0600, fmmu_regs(0x10000, 2, 0, 7, 0x1000, 0, 2))  # outputs
    m.apwr(0, 0x0610, fmmu_regs(0x10002, 2, 0, 7, 0x1002, 0, 1))  # inputs
    m.apwr(0, 0x1002, b"\xc0\xde")
    r = m.lrw(0x10000, b"\x12\x34\x00\x00")
    assert (r.data, r.wkc) == (b"\x12\x34\xc0\xde", 3)
    assert m.aprd(0, 0x1000, 2).data == b"\x12\x34"
    r = m.one(dg.build_logical(dg.Cmd.LRD, 0x10000, bytes(4)))
    assert (r.data, r.wkc) == (b"\x00\x00\xc0\xde", 1)
    r = m.one(dg.build_logical(dg.Cmd.LWR, 0x10000, b"\xab\xcd\xff\xff"))
    assert r.wkc == 1
    assert m.aprd(0, 0x1000, 4).data == b"\xab\xcd\xc0\xde"
    # outside every FMMU: no WKC
    assert m.lrw(0x20000, b"\x00").wkc == 0


def test_fmmu_bit_mapping() -> None:
    m, _ = setup()
    # logical bits 3..5 of byte 0x100 -> physical 0x1000 bits 0..2 (write)
    m.apwr(0, 0x0600, fmmu_regs(0x100, 1, 3, 5, 0x1000, 0, 2))
    # logical bits 6..9 (spanning two bytes) <- physical 0x1001 bits 4..7 (read)
    m.apwr(0, 0x0610, fmmu_regs(0x100, 2, 6, 1, 0x1001, 4, 1))
    m.apwr(0, 0x1000, b"\xf8\xa0")
    r = m.one(dg.build_logical(dg.Cmd.LRW, 0x100, b"\x28\x00"))  # bits 3 and 5 set
    assert r.wkc == 3
    assert m.aprd(0, 0x1000, 1).data == b"\xfd"  # 0xf8 | 0b101
    # physical 0x1001 = 0xa0 -> bits 4..7 = 0b1010 -> logical bits 6..9 = 0,1,0,1
    assert r.data == bytes([0x28 | (0 << 6) | (1 << 7), 0x02])


def test_two_slaves_lrw_wkc_adds_up() -> None:
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    for pos in (0, 1):
        m.apwr(pos, 0x0600, fmmu_regs(pos * 2, 2, 0, 7, 0x1000, 0, 2))
        m.apwr(pos, 0x0610, fmmu_regs(4 + pos * 2, 2, 0, 7, 0x1002, 0, 1))
        m.apwr(pos, 0x1002, bytes([0x10 + pos, 0x20 + pos]))
    r = m.lrw(0, b"\x01\x02\x03\x04\x00\x00\x00\x00")
    assert r.wkc == 6
    assert r.data == b"\x01\x02\x03\x04\x10\x20\x11\x21"
    assert m.aprd(1, 0x1000, 2).data == b"\x03\x04"


def test_sm_starting_in_register_space_does_not_hide_registers() -> None:
    """Found by the frame fuzzer: an SM placed over the registers must not lock a master
    out of its own configuration registers (decision E22)."""
    m, _ = setup()
    assert m.apwr(0, 0x0800, sm_regs(0x05A0, 0x4000, 0x26)).wkc == 1
    assert m.aprd(0, 0x0800, 7).data == sm_regs(0x05A0, 0x4000, 0x26)[:7]
    assert m.apwr(0, 0x0800, bytes(8)).wkc == 1  # the master disables it ...
    assert m.aprd(0, 0x0806, 1).data == b"\x00"
    assert m.apwr(0, 0x0800, bytes(8)).wkc == 1  # ... and, disabled, clears it
    assert m.aprd(0, 0x0800, 6).data == bytes(6)
    assert m.aprd(0, 0x0130, 2).wkc == 1


def test_fmmu_into_an_sm_window_follows_the_sm_being_switched_off_and_on() -> None:
    """An FMMU whose physical range lies in one SM window is routed straight to that SM
    (compiled when FMMUs or SMs change); with the SM off it writes plain memory again."""
    m, pdi = setup()
    esc = m.seg.escs[0]
    m.apwr(0, 0x0820, sm_regs(0x1800, 4, 0x64))  # SM4, 3-buffer, ECAT writes
    m.apwr(0, 0x0600, fmmu_regs(0x10000, 4, 0, 7, 0x1800, 0, 2))
    assert esc.fmmus[0].sm is esc.sm[4]
    assert m.lrw(0x10000, b"\x01\x02\x03\x04").wkc == 2
    assert pdi.sm_read(4) == b"\x01\x02\x03\x04"
    assert m.aprd(0, 0x0825, 1).data[0] & 0x30 == 0x00  # buffer exchanged: latest is 0
    m.apwr(0, 0x0826, b"\x00")  # SM4 off: the window is plain memory
    assert esc.fmmus[0].sm is None
    assert m.lrw(0x10000, b"\x05\x06\x07\x08").wkc == 2
    assert bytes(esc.mem[0x1800:0x1804]) == b"\x05\x06\x07\x08"
    m.apwr(0, 0x0826, b"\x01")
    assert esc.fmmus[0].sm is esc.sm[4]


def test_fmmu_spanning_a_window_and_plain_memory_is_not_routed() -> None:
    m, _ = setup()
    esc = m.seg.escs[0]
    m.apwr(0, 0x0820, sm_regs(0x1800, 2, 0x64))  # 2-byte window, then plain memory
    m.apwr(0, 0x0600, fmmu_regs(0x10000, 4, 0, 7, 0x1800, 0, 2))
    assert esc.fmmus[0].sm is None
    assert m.lrw(0x10000, b"\xaa\xbb\xcc\xdd").wkc == 2
    assert bytes(esc.mem[0x1802:0x1804]) == b"\xcc\xdd"
    assert m.aprd(0, 0x1800, 2).data == b"\xaa\xbb"  # through the SM's latest buffer
