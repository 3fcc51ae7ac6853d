"""The SyncManager's and the ESC's per-cycle paths through C pointers and the event
update of the changed bits only (decisions P27-P29) do what the checked, general paths
do: the same bytes, the same IndexError where a buffer runs past the 64 KiB memory,
and event registers that always mirror every SM's event bits. Run against the compiled
core and the pure-Python one alike.

Ref: TMC8460 §5.49 Tables 88-90 (SM status and buffer exchange), §5.31, §5.32 (event
requests).
"""

from __future__ import annotations

import random

import pytest

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.regs import (
    AL_EVENT_MASK,
    AL_EVENT_REQUEST,
    DC_SYSTEM_TIME_OFFSET,
    ECAT_EV_SM0,
    ECAT_EVENT_REQUEST,
    EV_SM0,
    SM_CTRL_ECAT_IRQ,
    SM_CTRL_PDI_IRQ,
    SM_DIR_READ,
    SM_DIR_WRITE,
    SM_MODE_BUFFERED,
    SM_MODE_MAILBOX,
)
from ecatsim.esc.sm import SyncManager

IRQS = SM_CTRL_ECAT_IRQ | SM_CTRL_PDI_IRQ


def esc() -> Esc:
    return Esc(0, FrameContext(), bytearray(b"\xff" * 256))


def test_the_32_and_64_bit_registers_keep_their_top_bits() -> None:
    """P27: the pointer reads of core._get32 and dc._get64 neither sign-extend nor
    truncate (bit 31 of 0x0220, bit 63 of 0x0920)."""
    e = esc()
    e.set_al_event(0x8000_0001)
    assert e.al_event() == 0x8000_0001
    assert e.mem[AL_EVENT_REQUEST : AL_EVENT_REQUEST + 4] == b"\x01\x00\x00\x80"
    e.clr_al_event(0x8000_0000)
    assert e.al_event() == 0x0000_0001
    e.mem[DC_SYSTEM_TIME_OFFSET : DC_SYSTEM_TIME_OFFSET + 8] = (0xFFFF_FFFF_0000_1234).to_bytes(
        8, "little"
    )
    assert e.dc.offset() == 0xFFFF_FFFF_0000_1234


def near_the_end(direction: int) -> SyncManager:
    """A 3-buffer SM whose second buffer runs 8 bytes past 0xFFFF."""
    sm = esc().sm[2]
    sm.configure(0xFFE8, 0x10, SM_MODE_BUFFERED | direction, True)
    return sm


def test_a_write_past_the_memory_raises_after_the_bytes_before_it() -> None:
    """P28: writer_write and write_whole copy through a pointer only where the buffer
    lies inside the memory; elsewhere the checked loop writes the bytes before the end
    and raises IndexError, as before."""
    data = bytes(range(1, 17))
    sm = near_the_end(SM_DIR_WRITE)
    sm.w = 1  # the buffer at 0xFFF8
    with pytest.raises(IndexError):
        sm.writer_write(0, data)
    assert sm.mem[0xFFF8:0x10000] == data[:8]
    sm = near_the_end(SM_DIR_READ)
    sm.w = 1
    with pytest.raises(IndexError):
        sm.write_whole(data)
    assert sm.mem[0xFFF8:0x10000] == data[:8]
    with pytest.raises(IndexError):
        sm.write_whole(data[:4])  # shorter than the buffer: raises, as the loop did
    sm.w = 0
    sm.write_whole(data)  # inside the memory: the pointer path
    assert sm.mem[0xFFE8:0xFFF8] == data


def test_a_read_past_the_memory_stops_where_it_does() -> None:
    """P28: read_whole of a buffer running past 0xFFFF returns the bytes up to the end
    (a slice stops there); reader_read raises IndexError after the bytes before it."""
    sm = near_the_end(SM_DIR_WRITE)
    sm.mem[0xFFE8:0x10000] = bytes(range(24))
    sm.l = 1
    assert sm.read_whole() == bytes(range(16, 24))
    sm.l = 0
    assert sm.read_whole() == bytes(range(16))
    sm.l = 1
    out = bytearray(16)
    with pytest.raises(IndexError):
        sm.reader_read(0, memoryview(out))
    assert out[:8] == bytes(range(16, 24))


def test_the_pointer_copies_are_the_byte_loops() -> None:
    """P28: ECAT writes and reads at every offset and length, and the PDI's whole
    buffer, give the bytes a plain copy gives."""
    for off in range(4):
        for n in range(1, 9 - off):
            w = esc().sm[2]
            w.configure(0x1000, 8, SM_MODE_BUFFERED | SM_DIR_WRITE, True)
            data = bytes(range(10 * off + n, 10 * off + 2 * n))
            for _ in range(3):  # into each buffer in turn
                base = w.start + w.w * w.length
                w.ecat_write(off, data)
                assert w.mem[base + off : base + off + n] == data
                w.ecat_write(0, bytes(8))
            r = esc().sm[3]
            r.configure(0x1100, 8, SM_MODE_BUFFERED | SM_DIR_READ, True)
            r.write_whole(bytes(range(100, 108)))
            out = bytearray(n)
            r.ecat_read(off, memoryview(out))
            assert out == bytes(range(100 + off, 100 + off + n))


def check_mirrors(e: Esc) -> None:
    """0x0210 bit 4+n and 0x0220 bit 8+n are SM n's event bits (``mirror``)."""
    ecat = e.mem[ECAT_EVENT_REQUEST] | (e.mem[ECAT_EVENT_REQUEST + 1] << 8)
    al = e.al_event()
    for sm in e.sm:
        assert bool(ecat & (ECAT_EV_SM0 << sm.n)) == bool(sm.mirror & 1), sm.n
        assert bool(al & (EV_SM0 << sm.n)) == bool(sm.mirror & 2), sm.n
    mask = int.from_bytes(e.mem[AL_EVENT_MASK : AL_EVENT_MASK + 4], "little")
    assert e.irq_line == bool(al & mask)
    assert (e.position in e.ctx.pending) == e.irq_line


def test_the_event_registers_mirror_every_sm_whatever_changed() -> None:
    """P29: Esc._sm_events sets or clears only the event bits of an SM that changed;
    after every access of a random sequence (ECAT and PDI, mailbox and 3-buffer SMs,
    restarts) the event registers still hold every SM's bits and the interrupt line
    follows them."""
    rnd = random.Random(33)
    e = esc()
    layout = [
        (0x1000, 16, SM_MODE_MAILBOX | SM_DIR_WRITE),
        (0x1100, 16, SM_MODE_MAILBOX | SM_DIR_READ),
        (0x1200, 8, SM_MODE_BUFFERED | SM_DIR_WRITE),
        (0x1300, 8, SM_MODE_BUFFERED | SM_DIR_READ),
    ]

    def restart(n: int) -> None:
        start, length, control = layout[n]
        e.sm[n].configure(start, length, control | (IRQS & rnd.choice((0, IRQS, 0x10, 0x20))), True)

    for n in range(4):
        restart(n)
    check_mirrors(e)
    for _ in range(3000):
        n = rnd.randrange(4)
        sm = e.sm[n]
        op = rnd.randrange(5)
        if op == 0 and sm.ecat_may_write():
            k = rnd.randrange(sm.length)
            sm.ecat_write(k, bytes(rnd.randrange(1, sm.length - k + 1)))
        elif op == 1 and sm.ecat_may_read():
            k = rnd.randrange(sm.length)
            sm.ecat_read(k, memoryview(bytearray(rnd.randrange(1, sm.length - k + 1))))
        elif op == 2 and sm.pdi_may_read():
            sm.read_whole()
        elif op == 3 and sm.pdi_may_write():
            sm.write_whole(bytes(sm.length))
        elif op == 4 and rnd.random() < 0.1:
            restart(n)
        check_mirrors(e)
