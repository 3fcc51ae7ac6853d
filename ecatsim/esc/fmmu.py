"""FMMU: logical-to-physical mapping at bit granularity, compiled when configured.

Ref: TMC8460 §5.48 Tables 75-84; ETG.1000.4 §6.6 (FMMU).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from ecatsim.esc.regs import FMMU_BASE, FMMU_STRIDE, N_FMMU
from ecatsim.wire.datagram import LRD, LRW, LWR  # compiled: C constants (fmmu.pxd)

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc
    from ecatsim.esc.sm import SyncManager

#: logical start u32, length u16, log start bit u8, log stop bit u8, phys start u16,
#: phys start bit u8, type u8, activate u8.  Ref: TMC8460 §5.48 Table 75.
FMMU_REG = struct.Struct("<IHBBHBBB")

TYPE_READ = 0x01
TYPE_WRITE = 0x02


class FmmuMap:
    """One active FMMU, compiled to bit addresses.

    ``lbit``/``lend`` span the logical bits [lbit, lend); ``pbit`` is the physical bit
    that the first logical bit maps to. ``aligned`` marks byte-aligned maps (fast path).
    ``sm`` is the SyncManager whose window holds the whole physical range, if exactly one
    does (set by the ESC whenever FMMUs or SM windows change): the copy goes straight to it.
    ``wnext``/``rnext``: the next FMMU of the same compiled tuple that writes / reads (set
    by ``compile_fmmus``; the frame walk follows them, decision P61).
    """

    __slots__ = (
        "aligned",
        "lbit",
        "lend",
        "lstart",
        "lstop",
        "pbit",
        "pstart",
        "read",
        "rnext",
        "sm",
        "wnext",
        "write",
    )

    def __init__(
        self, lstart: int, length: int, lsb: int, lstop: int, pstart: int, psb: int, typ: int
    ) -> None:
        self.lbit = lstart * 8 + (lsb & 7)
        self.lend = (lstart + length - 1) * 8 + (lstop & 7) + 1
        self.pbit = pstart * 8 + (psb & 7)
        self.read = bool(typ & TYPE_READ)
        self.write = bool(typ & TYPE_WRITE)
        self.aligned = (lsb & 7) == 0 and (lstop & 7) == 7 and (psb & 7) == 0
        self.lstart = lstart
        self.lstop = lstart + length
        self.pstart = pstart
        self.sm: SyncManager | None = None
        self.wnext: FmmuMap | None = None
        self.rnext: FmmuMap | None = None


def compile_fmmus(mem: bytearray) -> tuple[FmmuMap, ...]:
    """Compile the active FMMUs from their registers.

    An FMMU is active if its activate bit is set, its length is non-zero and it maps
    for reading or writing. Ref: TMC8460 §5.48 Tables 82, 83.
    """
    out: list[FmmuMap] = []
    if len(mem) < FMMU_BASE + N_FMMU * FMMU_STRIDE:
        raise IndexError(len(mem))
    p = mem  # compiled: a C pointer, the length checked above (P58)
    for n in range(N_FMMU):
        a = FMMU_BASE + n * FMMU_STRIDE
        # the inactive ones cost three loads: a broadcast clears them on every slave
        if not (p[a + 12] & 1) or (p[a + 4] | p[a + 5]) == 0 or not (p[a + 11] & 3):
            continue
        lstart, length, lsb, lstop, pstart, psb, typ, _act = FMMU_REG.unpack_from(mem, a)
        f = FmmuMap(lstart, length, lsb, lstop, pstart, psb, typ)
        if f.lend > f.lbit:
            out.append(f)
    w = r = None  # each FMMU to the next one that writes / reads
    for f in reversed(out):
        f.wnext = w
        f.rnext = r
        if f.write:
            w = f
        if f.read:
            r = f
    return tuple(out)


def logical_at(
    esc: Esc, fmmus: tuple[FmmuMap, ...], cmd: int, lad: int, buf: bytearray, pos: int, n: int
) -> int:
    """An LRD/LWR/LRW of ``buf[pos:pos + n]`` at logical address ``lad`` through the ESC's FMMUs
    (``fmmus``: ``esc.fmmus``, as ``compile_fmmus`` made them): writes use the datagram's data as
    received, then reads overlay it; returns the WKC increment, +1 for a read, +1 (LWR) or +2 (LRW)
    for a write. An FMMU given an SM (``FmmuMap.sm``) is one C call to it with pointers into the
    frame, the FMMUs followed through their links (the frame walk, decision P61); any other FMMU is
    the ESC's ``_fmmu_xfer`` with a view of the data.
    Ref: ETG.1000.4 §5.4.3 Table 12; TMC8460 §5.48."""
    if not fmmus:
        return 0
    wr = rd = False
    end = lad + n
    head = fmmus[0]
    if cmd != LRD:
        f = head if head.write else head.wnext
        while f is not None:
            if f.lstart < end and lad < f.lstop:  # lbit < hi and lo < lend, in bytes
                sm = f.sm
                a = max(lad, f.lstart)
                if sm is None:  # the ESC's own path, with a view of the datagram's data
                    wr |= bool(esc._fmmu_xfer(f, lad, memoryview(buf)[pos : pos + n], True))
                elif sm.ecat_write_at(
                    f.pstart + (a - f.lstart) - sm.start, buf, pos + a - lad, min(end, f.lstop) - a
                ):
                    wr = True
            f = f.wnext
    if cmd != LWR:
        f = head if head.read else head.rnext
        while f is not None:
            if f.lstart < end and lad < f.lstop:
                sm = f.sm
                a = max(lad, f.lstart)
                if sm is None:
                    rd |= bool(esc._fmmu_xfer(f, lad, memoryview(buf)[pos : pos + n], False))
                elif sm.ecat_read_at(
                    f.pstart + (a - f.lstart) - sm.start, buf, pos + a - lad, min(end, f.lstop) - a
                ):
                    rd = True
            f = f.rnext
    if cmd == LRW:
        return (1 if rd else 0) + (2 if wr else 0)
    return 1 if (rd or wr) else 0


def copy_bits(
    src: bytes | bytearray | memoryview,
    sbit: int,
    dst: bytearray | memoryview,
    dbit: int,
    n: int,
) -> None:
    """Copy ``n`` bits from ``src`` at bit ``sbit`` to ``dst`` at bit ``dbit`` (LSB first).

    Ref: TMC8460 §5.48 Tables 78, 79, 81 (bits counted from the least significant bit).
    """
    sb = sbit >> 3
    se = (sbit + n + 7) >> 3
    v = (int.from_bytes(src[sb:se], "little") >> (sbit & 7)) & ((1 << n) - 1)
    db = dbit >> 3
    de = (dbit + n + 7) >> 3
    sh = dbit & 7
    m = ((1 << n) - 1) << sh
    d = int.from_bytes(dst[db:de], "little")
    dst[db:de] = ((d & ~m) | (v << sh)).to_bytes(de - db, "little")
