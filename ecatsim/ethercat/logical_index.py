# cython: boundscheck=False, wraparound=False
"""The logical datagrams' way through a segment: only the ESCs whose FMMUs the datagram's
logical range reaches, in wire order.

An LRD, LWR or LRW passes every slave, and each slave's FMMUs decide whether it reads or
writes (ETG.1000.4 §5.4.3 Table 12; TMC8460 §5.48); a slave none of whose FMMUs overlaps
the datagram's bytes neither reads, writes nor counts. A master cuts a large process
image into several frames (SOEM: 1486 bytes of an LRW each), so each frame reaches only
part of the slaves. The index holds every active FMMU's logical byte range sorted by its
start; a datagram looks up the FMMUs its range can overlap and runs
:func:`ecatsim.esc.fmmu.logical_at` for their ESCs only, in wire order. The ESCs it skips
are those where ``logical_at`` would find no overlap and do nothing, so the results are
the same (decision P99). Small segments, and a datagram that spans every FMMU, take the
plain walk over all ESCs with FMMUs.
"""

from __future__ import annotations

from array import array

from ecatsim.esc.core import Esc
from ecatsim.esc.fmmu import logical_at

#: fewer ESCs with FMMUs than this: every logical datagram walks them all (the lookup
#: would cost more than the calls it saves)
INDEX_MIN = 32


class LogicalIndex:
    """The active FMMUs of one segment's route, sorted by logical start (``build``), and
    the walk of a logical datagram through the ESCs they belong to (``walk``)."""

    #: fixed attributes (the compiled core declares them in logical_index.pxd)
    __slots__ = (
        "_k",
        "_last",
        "_mark",
        "_reach",
        "_start",
        "_stop",
        "escs",
        "on",
        "visits",
    )

    def __init__(self) -> None:
        #: the ESCs with FMMUs in wire order (the segment's ``logical`` list)
        self.escs: list[Esc] = []
        #: per FMMU, sorted by logical start: its start, its stop (bytes, exclusive), and
        #: its ESC's place in ``escs``
        self._start = array("q")
        self._stop = array("q")
        self._k = array("q")
        #: the longest FMMU (bytes): one that starts this far before a datagram or more
        #: ends before it
        self._reach = 0
        #: the highest stop of all FMMUs (the lowest start is ``_start[0]``)
        self._last = 0
        #: per ESC: reached by the datagram being walked (cleared as the walk goes)
        self._mark = bytearray()
        #: look up the FMMUs (False: every datagram walks every ESC; the tests' reference)
        self.on = True
        #: the ESCs the logical datagrams were walked through, all told
        self.visits = 0

    def build(self, escs: list[Esc]) -> None:
        """Index the FMMUs of ``escs`` (in wire order, each with FMMUs), after any change
        of an FMMU, of the route or of the ESCs in it (the segment's ``logical_dirty``)."""
        spans = sorted((f.lstart, f.lstop, k) for k, esc in enumerate(escs) for f in esc.fmmus)
        self.escs = escs
        self._start = array("q", [s[0] for s in spans])
        self._stop = array("q", [s[1] for s in spans])
        self._k = array("q", [s[2] for s in spans])
        self._reach = max((b - a for a, b, _ in spans), default=0)
        self._last = max((b for _, b, _ in spans), default=0)
        self._mark = bytearray(len(escs))

    def walk(self, cmd: int, lad: int, buf: bytearray, d0: int, dlen: int) -> int:
        """The datagram ``buf[d0:d0 + dlen]`` (command ``cmd``, logical address ``lad``)
        through every ESC whose FMMUs reach it, in wire order: its WKC increment.
        Ref: ETG.1000.4 §5.4.3 Table 12."""
        escs = self.escs
        inc = 0
        end = lad + dlen
        # (32 or more ESCs with FMMUs: ``_start`` is not empty)
        if not self.on or len(escs) < INDEX_MIN or (lad <= self._start[0] and end >= self._last):
            for esc in escs:
                inc += logical_at(esc, esc.fmmus, cmd, lad, buf, d0, dlen)
            self.visits += len(escs)
            return inc
        start = self._start
        stop = self._stop
        ks = self._k
        mark = self._mark
        n = len(start)
        # the first FMMU that may reach the datagram: starts after lad - reach
        key = lad - self._reach
        lo = 0
        hi = n
        while lo < hi:
            mid = (lo + hi) >> 1
            if start[mid] <= key:
                lo = mid + 1
            else:
                hi = mid
        kmin = len(escs)
        kmax = -1
        j = lo
        while j < n and start[j] < end:
            if stop[j] > lad:
                k = ks[j]
                mark[k] = 1
                if k < kmin:
                    kmin = k
                if k > kmax:
                    kmax = k
            j += 1
        # wire order; a mark an exception left behind costs one call that finds nothing
        for k in range(kmin, kmax + 1):
            if mark[k]:
                mark[k] = 0
                esc = escs[k]
                inc += logical_at(esc, esc.fmmus, cmd, lad, buf, d0, dlen)
                self.visits += 1
        return inc
