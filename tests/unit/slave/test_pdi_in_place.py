"""The process data without bytes objects (decisions P70, P71): SM3 filled in place by the
process image (``Pdi.sm_fill``) and SM2 read into the firmware's own buffer
(``Pdi.sm_read_into``) give exactly what ``sm_write`` of ``pack_inputs()`` and
``sm_read`` gave: the same memory (buffers, status and event registers, event times),
SM state, PDI interrupt line, return values and decoded outputs, for every TxPDO/RxPDO
mapping the TMC8670 allows, values in and out of their fields' ranges, 3-buffer and
mailbox SMs, SM lengths other than the image's and buffers at the memory's end. Run
against the compiled core and the pure-Python one alike.

Ref: TMC8460 §5.49 Tables 88-91 (SM buffers, status, activation bit 7), §5.50.6 (PDI
event times); ETG.1000.6 §5.6.7.4 (PDO mapping).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import replace

from ecatsim.device.description import default_description
from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.pdi import Pdi
from ecatsim.esc.regs import (
    SM_ACT_LATCH_PDI,
    SM_CTRL_ECAT_IRQ,
    SM_CTRL_PDI_IRQ,
    SM_DIR_READ,
    SM_DIR_WRITE,
    SM_MODE_BUFFERED,
    SM_MODE_MAILBOX,
)
from ecatsim.esc.sm import SyncManager
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import PdoImage, Plan, compile_plan
from tests.support.pdo_mappings import every_mapping, set_mapping

IRQS = SM_CTRL_ECAT_IRQ | SM_CTRL_PDI_IRQ
STATE = ("w", "l", "r", "r_open", "w_open", "mbx_full", "status", "mirror", "changed")


class Quiet:
    def outputs_applied(self, now_ns: int) -> None: ...

    def update_inputs(self, now_ns: int) -> None: ...

    def al_state_changed(self, state: object, now_ns: int) -> None: ...


def _value(rnd: random.Random, bits: int, signed: bool, wild: bool) -> int:
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    if not wild:
        return rnd.randint(lo, hi)
    return rnd.choice([lo, hi, lo - 1, hi + 1, -1, 1 << 40, -(1 << 70), 1 << 64, True, 7])


def twin(start: int, length: int, control: int, latch: bool) -> tuple[Esc, Pdi, SyncManager]:
    """An ESC with SM ``n`` configured, its buffers holding other bytes than any image."""
    e = Esc(0, FrameContext(), bytearray(b"\xff" * 256))
    n = 3 if control & SM_DIR_WRITE == 0 else 2
    for a in range(start, min(start + 3 * length, len(e.mem))):
        e.mem[a] = (a * 7 + 3) & 0xFF
    sm = e.sm[n]
    sm.configure(start, length, control, True)
    if latch:  # 0x0806+8n bit 7: the PDI event times (Pdi's buffer event)
        e.mem[sm.status_addr + 1] |= SM_ACT_LATCH_PDI
    return e, Pdi(e), sm


def attempt(write: Callable[[int, bytes], bool], data: bytes) -> object:
    """SM3 written the general way: its result, or the error it raised (a buffer past
    the memory's end raises IndexError after the bytes before it, P28)."""
    try:
        return write(3, data)
    except IndexError:
        return IndexError


def ecat(access: Callable[[int, bytearray, int, int], bool], buf: bytearray, n: int) -> object:
    """The master's access of the window's first ``n`` bytes: whether it counts, or the
    error it raised past the memory's end."""
    try:
        return access(0, buf, 0, n)
    except IndexError:
        return IndexError


def same(a: tuple[Esc, Pdi, SyncManager], b: tuple[Esc, Pdi, SyncManager]) -> None:
    assert a[0].mem == b[0].mem
    assert [getattr(a[2], k) for k in STATE] == [getattr(b[2], k) for k in STATE]
    assert a[0].irq_line == b[0].irq_line
    assert a[0].ctx.pending == b[0].ctx.pending


def test_sm3_filled_in_place_is_sm_write_of_the_packed_inputs() -> None:
    """P71: per TxPDO mapping, random values (in range; out of range, bools, beyond 64 bits:
    then the image declines and the general path writes), 3-buffer and mailbox SMs of the
    image's length and others, with and without PDI event times, the master reading the
    buffers in between: the same memory, state, events and return values. Where the image
    declines, the SM's buffer is untouched."""
    rnd = random.Random(71)
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    filled = declined = 0
    for mapping in every_mapping(od, False):
        set_mapping(od, 0x1A00, mapping)
        plan = compile_plan(od)
        img.plan = plan
        assert plan.tx_codec is not None and plan.tx_codec.layout is not None
        fields = [f for f in plan.tx if f.entry is not None]
        size = plan.tx_size
        for mode in (SM_MODE_BUFFERED, SM_MODE_MAILBOX):
            for length in {size, size + 3, max(2, size - 1)}:
                for start in (0x1000, 0x10000 - 2 * length):  # the last buffers past the end
                    control = mode | SM_DIR_READ | IRQS
                    latch = rnd.random() < 0.5
                    old = twin(start, length, control, latch)
                    new = twin(start, length, control, latch)
                    for step in range(40):
                        wild = rnd.random() < 0.3
                        for f in fields:
                            assert f.entry is not None
                            signed = f.entry.dtype.startswith("INTEGER")
                            f.entry.value = _value(rnd, f.size * 8, signed, wild)
                        for t in (old, new):
                            t[0].ctx.pdi_ns = 1000 * step
                        if rnd.random() < 0.7:
                            ok_old = attempt(old[1].sm_write, img.pack_inputs())
                            before = bytes(new[0].mem)
                            if new[1].sm_fill(3, img):
                                ok_new: object = True
                                filled += 1
                            else:
                                assert new[0].mem == before  # declined: nothing written
                                declined += 1
                                ok_new = attempt(new[1].sm_write, img.pack_inputs())
                            assert ok_old == ok_new
                        else:  # the master reads the buffer, whole or its start
                            n = length if rnd.random() < 0.7 else 1
                            bufs = [bytearray(n), bytearray(n)]
                            got = [
                                ecat(t[2].ecat_read_at, b, n)
                                for t, b in zip((old, new), bufs, strict=True)
                            ]
                            assert got[0] == got[1] and bufs[0] == bufs[1]
                        same(old, new)
    assert filled > 100 and declined > 100, (filled, declined)  # both ways taken


def test_sm2_read_into_the_buffer_is_sm_read() -> None:
    """P70: the outputs read into a buffer the caller keeps are ``sm_read``'s bytes, with
    the same SM state and events, for 3-buffer and mailbox SMs, buffers running past the
    memory's end (the bytes up to it) and a buffer of another length before; None / False
    alike where SM2 is not readable."""
    rnd = random.Random(70)
    for mode in (SM_MODE_BUFFERED, SM_MODE_MAILBOX):
        for length in (2, 12, 17):
            for start in (0x1000, 0x10000 - length - 3, 0x10000 - 2 * length - 1):
                control = mode | SM_DIR_WRITE | IRQS
                latch = rnd.random() < 0.5
                old = twin(start, length, control, latch)
                new = twin(start, length, control, latch)
                out = bytearray(rnd.randrange(5))
                for step in range(40):
                    for t in (old, new):
                        t[0].ctx.pdi_ns = 1000 * step
                    if rnd.random() < 0.5:
                        data = rnd.randbytes(length)
                        n = length if rnd.random() < 0.8 else 1
                        got = [ecat(t[2].ecat_write_at, bytearray(data), n) for t in (old, new)]
                        assert got[0] == got[1]
                    else:
                        want = old[1].sm_read(2)
                        keep = bytes(out)
                        if new[1].sm_read_into(2, out):
                            assert want is not None and bytes(out) == want
                        else:
                            assert want is None and bytes(out) == keep
                    same(old, new)


def test_the_latched_outputs_stay_while_the_master_writes_sm2_again() -> None:
    """P70 with P30: once read, the 3-buffer SM may hand the buffer just read to the next
    ECAT write (the reader holds it only during its read), so the firmware's latch copies
    the outputs: two more writes reuse that buffer, the copy keeps the latched bytes."""
    e, p, sm = twin(0x1000, 8, SM_MODE_BUFFERED | SM_DIR_WRITE | IRQS, False)
    sm.ecat_write_at(0, bytearray(b"AAAAAAAA"), 0, 8)
    out = bytearray()
    assert p.sm_read_into(2, out) and out == b"AAAAAAAA"
    read_at = sm.start + sm.r * sm.length
    sm.ecat_write_at(0, bytearray(b"BBBBBBBB"), 0, 8)
    sm.ecat_write_at(0, bytearray(b"CCCCCCCC"), 0, 8)
    assert e.mem[read_at : read_at + 8] != b"AAAAAAAA"  # the buffer read was reused
    assert out == b"AAAAAAAA"


def test_outputs_decoded_from_the_buffer_are_those_decoded_from_bytes() -> None:
    """P70: ``set_outputs`` of the firmware's bytearray gives the entries the values of
    ``set_outputs`` of the same bytes, on the C decoder, the struct and per-entry paths."""
    rnd = random.Random(72)
    od = build_od(default_description())
    img = PdoImage(od, Quiet())
    for mapping in every_mapping(od, True):
        set_mapping(od, 0x1600, mapping)
        plan = compile_plan(od)
        codec_ = plan.rx_codec
        assert codec_ is not None
        entries = [f.entry for f in plan.rx if f.entry is not None]
        for p in (plan, replace(plan, rx_codec=replace(codec_, layout=None)),
                  Plan(plan.rx, plan.tx, plan.rx_size, plan.tx_size)):  # fmt: skip
            img.plan = p
            for _ in range(10):
                data = rnd.randbytes(plan.rx_size + rnd.choice((0, 0, 2, -1)))
                img.set_outputs(data, 0)
                want = [e.value for e in entries]
                for e in entries:
                    e.value = "unset"
                img.set_outputs(bytearray(data), 0)
                assert [e.value for e in entries] == want
