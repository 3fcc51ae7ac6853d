"""The cache lines a cyclic frame reads, for the compiled responder to prefetch as its
wait ends (decision P18): on a CPU shared with the master each of the walk's dependent
reads (segment, frame context, ESC, FMMU map, SM, ESC memory) would otherwise be a cache
miss paid in series. A prefetch never faults, so a stale address costs nothing but the
look; tests/unit/test_serve.py checks that the list names what a cyclic frame reads."""

from __future__ import annotations

from ecatsim.ethercat.segment import Segment

#: the ESC memory a cyclic frame reads besides the mapped SMs' buffers: the ECAT event,
#: AL event, SM and DC registers. Ref: TMC8460 §5 (register map)
REGISTER_LINES = ((0x0100, 0x0140), (0x0200, 0x0240), (0x0800, 0x0880), (0x0900, 0x0940))


def hot_lines(seg: Segment) -> tuple[list[object], list[tuple[bytearray, int, int]]]:
    """The objects (their structs) and the (memory, start, stop) ranges of each ESC's
    memory a cyclic frame of ``seg`` reads: the registers above and the three buffers of
    each SM an FMMU maps."""
    objs: list[object] = [seg, seg.ctx, seg.escs, seg.logical]
    ranges: list[tuple[bytearray, int, int]] = []
    for esc in seg.escs:
        mem = esc.mem
        objs += [esc, esc.dc, esc.wd, esc.fmmus, mem]
        for start, stop in REGISTER_LINES:
            ranges.append((mem, start, stop))
        for f in esc.fmmus:
            objs.append(f)
            sm = f.sm
            if sm is not None:
                objs.append(sm)
                ranges.append((mem, sm.start, sm.start + 3 * sm.length))
    return objs, ranges
