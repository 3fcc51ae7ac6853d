"""The reference for logical datagrams: an LRD/LWR/LRW through every FMMU of an ESC, one
``Esc._fmmu_xfer`` per FMMU and a memoryview of the data, the plain reading of the
standard that ``ecatsim.esc.fmmu.logical_at`` (pointers into the frame, SM calls, the
FMMUs' links) must match. Ref: ETG.1000.4 §5.4.3 Table 12; TMC8460 §5.48."""

from __future__ import annotations

from ecatsim.esc.core import Esc
from ecatsim.wire.datagram import Cmd


def ecat_logical(esc: Esc, cmd: int, lad: int, data: memoryview) -> int:
    """Writes use the datagram's data as received, then reads overlay it. WKC: +1 for a
    read, +1 (LWR) or +2 (LRW) for a write, per slave."""
    lo = lad * 8
    hi = lo + len(data) * 8
    wr = rd = False
    if cmd != Cmd.LRD:
        for f in esc.fmmus:
            if f.write and f.lbit < hi and lo < f.lend and esc._fmmu_xfer(f, lad, data, True):
                wr = True
    if cmd != Cmd.LWR:
        for f in esc.fmmus:
            if f.read and f.lbit < hi and lo < f.lend and esc._fmmu_xfer(f, lad, data, False):
                rd = True
    if cmd == Cmd.LRW:
        return (1 if rd else 0) + (2 if wr else 0)
    return 1 if (rd or wr) else 0
