"""The frame walk's logical path (``fmmu.logical_at`` with ``SyncManager.ecat_write_at`` /
``ecat_read_at``, decisions P61, P62) does what the reference does (one ``_fmmu_xfer`` per FMMU,
tests/support/logical_ref.py): the same bytes in the datagram and the memory, the same WKC, SM
status, AL and ECAT event registers and interrupt line, for mailbox and 3-buffer SMs, read and
write, the watchdog bit, a locked SM, an SM with the ECAT event time bit, an FMMU split over two
SMs, a bit-wise FMMU and FMMUs into plain memory. Run against the compiled core and the pure-Python
one alike.

Ref: ETG.1000.4 §5.4.3 Table 12; TMC8460 §5.48, §5.49 Tables 86-91.
"""

from __future__ import annotations

import random
import struct

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.fmmu import logical_at
from ecatsim.esc.regs import FMMU_BASE, N_FMMU, SM_CTRL_WATCHDOG
from ecatsim.wire.datagram import LRD, LRW, LWR
from tests.support.logical_ref import ecat_logical

#: (start, length, control) of SMs 0-5: mailbox out/in, 3-buffer out/in with interrupts
SMS = [
    (0x1000, 16, 0x26),
    (0x1080, 16, 0x22),
    (0x1100, 12, 0x64 | SM_CTRL_WATCHDOG),
    (0x1200, 17, 0x30),
    (0x1300, 8, 0x20),
    (0x1400, 4, 0x24),
]
#: (logical start, length, log start bit, log stop bit, phys start, phys bit, type)
FMMUS = [
    (0x0000, 12, 0, 7, 0x1100, 0, 2),  # outputs -> SM2
    (0x0010, 17, 0, 7, 0x1200, 0, 1),  # inputs <- SM3
    (0x0030, 16, 0, 7, 0x1000, 0, 3),  # the mailboxes, read and write
    (0x0040, 1, 2, 5, 0x1300, 3, 1),  # a bit-wise map (the ESC's own path)
    (0x0050, 24, 0, 7, 0x12F8, 0, 3),  # split: plain memory and SM4 (no SM given)
    (0x0070, 4, 0, 7, 0x1400, 0, 3),  # SM5
]


def make(rnd: random.Random, ctx: FrameContext) -> Esc:
    e = Esc(0, ctx, bytearray(b"\xff" * 256))
    e.pdram_ok = True
    m = e.mem
    m[0x0204:0x0208] = b"\xff\xff\xff\xff"  # AL event mask: every event raises the line
    m[0x0200:0x0202] = b"\xff\xff"  # ECAT event mask
    for n, (start, length, control) in enumerate(SMS):
        e.sm[n].configure(start, length, control, True, locked=(n == 5 and rnd.random() < 0.5))
        if n == 3 and rnd.random() < 0.5:
            m[e.sm[n].status_addr + 1] |= 0x40  # ECAT event time: the window path
    for n, (ls, ln, lsb, lstop, ps, psb, typ) in enumerate(FMMUS[:N_FMMU]):
        a = FMMU_BASE + 16 * n
        m[a : a + 16] = struct.pack("<IHBBHBBB3x", ls, ln, lsb, lstop, ps, psb, typ, 1)
    e._ec_fmmu(FMMU_BASE, 16 * N_FMMU, bytes(16 * N_FMMU))
    e._compile_sm_windows()
    return e


def state(e: Esc) -> tuple[object, ...]:
    return (
        bytes(e.mem),
        e.irq_line,
        e.ecat_irq,
        tuple(e.ctx.raised),
        e.wd.deadline_ns,
        tuple((s.w, s.l, s.r, s.r_open, s.w_open, s.mbx_full, s.mirror) for s in e.sm),
    )


def test_logical_at_is_ecat_logical() -> None:
    for seed in range(12):
        rnd = random.Random(seed)
        a = make(random.Random(seed), FrameContext())
        b = make(random.Random(seed), FrameContext())
        assert state(a) == state(b)
        routed = sum(f.sm is not None for f in a.fmmus)
        assert 3 <= routed < len(a.fmmus)  # both paths are taken
        for step in range(300):
            cmd = rnd.choice((LRD, LWR, LRW))
            lad = rnd.randrange(0, 0x80)
            n = rnd.randrange(1, 0x50)
            data = bytes(rnd.randrange(256) for _ in range(n))
            a.ctx.t_ns = b.ctx.t_ns = 1_000_000 * (step + 1)
            view = bytearray(data)
            wkc_a = ecat_logical(a, cmd, lad, memoryview(view))
            frame = bytearray(rnd.randrange(64)) + bytearray(data) + bytearray(3)
            pos = len(frame) - n - 3
            wkc_b = logical_at(b, b.fmmus, cmd, lad, frame, pos, n)
            assert (wkc_a, bytes(view)) == (wkc_b, bytes(frame[pos : pos + n])), (seed, step)
            assert state(a) == state(b), (seed, step)
            if rnd.random() < 0.3:  # the PDI side empties and fills the buffers
                for e in (a, b):
                    for sm in e.sm:
                        if sm.pdi_may_read():
                            sm.read_whole()
                        elif sm.pdi_may_write():
                            sm.write_whole(bytes(range(sm.length)))
                assert state(a) == state(b), (seed, step)


def test_a_read_of_the_written_buffer_has_no_side_effects() -> None:
    """An LRD of an output SM (written by the ECAT) reads the latest buffer back and
    changes no state, on both paths."""
    e = make(random.Random(1), FrameContext())
    ecat_logical(e, LWR, 0, memoryview(bytearray(range(1, 13))))
    before = state(e)
    sm = e.sm[2]
    out = bytearray(12)
    assert sm.ecat_read_at(0, out, 0, 12)
    assert out == bytes(range(1, 13))
    assert state(e) == before
