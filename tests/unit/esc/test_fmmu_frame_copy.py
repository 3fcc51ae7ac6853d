"""An FMMU's part of a datagram goes between the frame and an SM's buffer without a view of
it (``SyncManager.ecat_write_from`` / ``ecat_read_into``, decision P61): the same memory,
SM state, events, watchdog and event time as ``ecat_write`` / ``ecat_read`` of the slice,
the same IndexError (after the same bytes) where a buffer runs past the 64 KiB memory.
Run against the compiled core and the pure-Python one alike.

Ref: TMC8460 §5.48 (FMMU), §5.49 Tables 87-90 (SM control, status, buffer exchange).
"""

from __future__ import annotations

import pytest

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.regs import (
    SM_ACT_LATCH_ECAT,
    SM_CTRL_ECAT_IRQ,
    SM_CTRL_PDI_IRQ,
    SM_CTRL_WATCHDOG,
    SM_DIR_READ,
    SM_DIR_WRITE,
    SM_MODE_BUFFERED,
    SM_MODE_MAILBOX,
)
from ecatsim.esc.sm import SyncManager

FRAME = bytes(range(7, 7 + 64))


def twin(control: int, start: int = 0x1000, length: int = 12) -> tuple[Esc, Esc]:
    """Two ESCs alike, SM 2 configured and enabled, the event time latched at the buffer
    exchange (0x0806 bit 6), the frame's time set."""
    pair = []
    for _ in range(2):
        ctx = FrameContext()
        ctx.t_ns = 123_456_789
        e = Esc(0, ctx, bytearray(b"\xff" * 256))
        sm = e.sm[2]
        sm.configure(start, length, control, True)
        e.mem[sm.status_addr + 1] |= SM_ACT_LATCH_ECAT
        pair.append(e)
    return pair[0], pair[1]


def same(a: Esc, b: Esc) -> None:
    sa: SyncManager = a.sm[2]
    sb: SyncManager = b.sm[2]
    assert a.mem == b.mem
    fields = ("w", "l", "r", "r_open", "w_open", "status", "mbx_full", "mirror")
    assert [getattr(sa, f) for f in fields] == [getattr(sb, f) for f in fields]
    assert a.wd.deadline_ns == b.wd.deadline_ns
    assert a.al_event() == b.al_event()


@pytest.mark.parametrize("mode", [SM_MODE_BUFFERED, SM_MODE_MAILBOX])
@pytest.mark.parametrize("irq", [0, SM_CTRL_ECAT_IRQ | SM_CTRL_PDI_IRQ])
def test_a_write_from_the_frame_is_the_write_of_its_slice(mode: int, irq: int) -> None:
    fast, slow = twin(mode | SM_DIR_WRITE | SM_CTRL_WATCHDOG | irq)
    fast.wd.deadline_ns = slow.wd.deadline_ns = 0
    frame = bytearray(FRAME)
    for off, a, n in ((0, 5, 12), (0, 9, 4), (4, 20, 8), (0, 0, 12), (3, 30, 9)):
        sf, ss = fast.sm[2], slow.sm[2]
        if not sf.ecat_may_write():  # a full mailbox: the PDI empties it
            sf.read_whole()
            ss.read_whole()
        assert sf.ecat_may_write() and ss.ecat_may_write()
        sf.ecat_write_from(off, frame, a, n)
        ss.ecat_write(off, memoryview(frame)[a : a + n])
        same(fast, slow)
    assert fast.wd.deadline_ns != 0  # the process-data watchdog was triggered
    assert frame == FRAME  # the frame is only read


@pytest.mark.parametrize("mode", [SM_MODE_BUFFERED, SM_MODE_MAILBOX])
@pytest.mark.parametrize("direction", [SM_DIR_READ, SM_DIR_WRITE])
def test_a_read_into_the_frame_is_the_read_into_its_slice(mode: int, direction: int) -> None:
    """ECAT reads of a read SM (the buffer exchange, the event time) and of a write SM
    (the newest buffer, no side effect) alike."""
    fast, slow = twin(mode | direction | SM_CTRL_ECAT_IRQ | SM_CTRL_PDI_IRQ)
    ff, fs = bytearray(FRAME), bytearray(FRAME)
    for k, (off, a, n) in enumerate(((0, 5, 12), (0, 40, 6), (6, 2, 6), (0, 0, 12))):
        sf, ss = fast.sm[2], slow.sm[2]
        if direction == SM_DIR_READ and sf.pdi_may_write():
            data = bytes(range(100 + k, 112 + k))  # the PDI fills the next buffer
            sf.write_whole(data)
            ss.write_whole(data)
        if not sf.ecat_may_read():
            assert not ss.ecat_may_read()
            continue
        sf.ecat_read_into(off, ff, a, n)
        ss.ecat_read(off, memoryview(fs)[a : a + n])
        assert ff == fs
        same(fast, slow)
    assert ff != FRAME or direction == SM_DIR_WRITE


def test_past_the_memory_end_both_raise_after_the_same_bytes() -> None:
    """A 3-buffer SM whose second buffer runs 8 bytes past 0xFFFF."""
    fast, slow = twin(SM_MODE_BUFFERED | SM_DIR_WRITE, start=0xFFE8, length=0x10)
    for e in (fast, slow):
        e.sm[2].w = 1  # the buffer at 0xFFF8
    frame = bytearray(FRAME)
    with pytest.raises(IndexError):
        fast.sm[2].ecat_write_from(0, frame, 3, 16)
    with pytest.raises(IndexError):
        slow.sm[2].ecat_write(0, memoryview(frame)[3:19])
    assert fast.mem[0xFFF8:] == slow.mem[0xFFF8:] == FRAME[3:11]
    fast, slow = twin(SM_MODE_BUFFERED | SM_DIR_READ, start=0xFFE8, length=0x10)
    for e in (fast, slow):
        e.mem[0xFFE8:] = bytes(range(24))
        e.sm[2].l = 1
    ff, fs = bytearray(FRAME), bytearray(FRAME)
    with pytest.raises(IndexError):
        fast.sm[2].ecat_read_into(0, ff, 10, 16)
    with pytest.raises(IndexError):
        slow.sm[2].ecat_read(0, memoryview(fs)[10:26])
    assert ff == fs
    assert ff[10:18] == bytes(range(16, 24))
