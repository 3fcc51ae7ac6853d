"""The CiA 402 drive's objects as its cycle uses them: each entry looked up once with its
integer range, the controls and set points bound to typed fields, and the values the drive
publishes each cycle kept as C integers, written into their entries only when something
reads the object dictionary. The base of :class:`ecatsim.device.drive.Drive`.

Ref: CiA 402-2 §6 (objects), TMC8670 Tables 80-83; decisions P34, P38, P51, P90.
"""

from __future__ import annotations

from array import array

from ecatsim.slave.od import Entry, ObjectDictionary
from ecatsim.slave.pdo import CycleDevice

_MISSING = object()
#: actual values refreshed at every input update, in the order _publish() computes them
PUBLISHED = (0x6041, 0x6061, 0x6064, 0x606C, 0x6062, 0x606B, 0x6077, 0x6074, 0x60F4, 0x603F)
#: OD values the substeps use, read once per advance() into the q_ attributes, in order
SNAPSHOT = (0x60FF, 0x6083, 0x6084, 0x607A, 0x60B0, 0x60B1, 0x6071, 0x60B2, 0x6065, 0x6085, 0x605A)
#: the RxPDO values every outputs_applied() reads: controlword, mode, position target
CONTROLS = (0x6040, 0x6060, 0x607A)


class DriveOd(CycleDevice):
    """The drive's object dictionary view (a CycleDevice: the process image calls the
    drive's cycle in C)."""

    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self._entries: dict[int, tuple[Entry, int, int] | None] = {}
        #: the entries _publish() writes every cycle, in PUBLISHED order (looked up once)
        self._published: tuple[tuple[Entry, int, int] | None, ...] | None = None
        #: the entries of SNAPSHOT and CONTROLS (None: not in the OD), looked up once
        self._snapshot_hits: tuple[Entry | None, ...] | None = None
        self._control_hits: tuple[Entry | None, ...] | None = None
        #: the same entries one by one: typed fields in the compiled core, read without a
        #: tuple's item and type test each cycle (decision P51); set by _bind()
        self._bound = False
        self._c_6040: Entry | None = None
        self._c_6060: Entry | None = None
        self._c_607a: Entry | None = None
        self._s_60ff: Entry | None = None
        self._s_6083: Entry | None = None
        self._s_6084: Entry | None = None
        self._s_607a: Entry | None = None
        self._s_60b0: Entry | None = None
        self._s_60b1: Entry | None = None
        self._s_6071: Entry | None = None
        self._s_60b2: Entry | None = None
        self._s_6065: Entry | None = None
        self._s_6085: Entry | None = None
        self._s_605a: Entry | None = None
        #: the published entries' ranges as C integers (P34; C arrays: P90), set with _published
        self._pub_c = False
        self._pub_lo: list[int]  # one per PUBLISHED index (compiled: zero from the start)
        self._pub_hi: list[int]
        #: the values _publish() computed last, in PUBLISHED order, and whether the OD
        #: entries still wait for them (P38: written when something reads the OD)
        self.pub_values = array("q")
        self.pub_pending = False
        od.flush = self.pub_flush  # whatever reads the OD sees the values kept here

    # ----------------------------------------------------------------- OD helpers
    def _entry(self, index: int, sub: int) -> tuple[Entry, int, int] | None:
        """The OD entry (with its integer range), looked up once: the OD's entries are
        fixed objects, only their values change."""
        key = (index << 8) | sub
        hit = self._entries.get(key, _MISSING)
        if hit is not _MISSING:
            return hit  # type: ignore[return-value]
        found: tuple[Entry, int, int] | None = None
        if index in self.od:
            e = self.od.entry(index, sub)
            bits = e.bits
            if e.dtype.startswith("INTEGER"):
                found = (e, -(1 << (bits - 1)), (1 << (bits - 1)) - 1)
            else:
                found = (e, 0, (1 << bits) - 1)
        self._entries[key] = found
        return found

    def _v(self, index: int, sub: int = 0) -> int:
        if self.pub_pending:
            self.pub_flush()
        hit = self._entry(index, sub)
        if hit is None:
            return 0
        e = hit[0]
        v = e.value
        return v if isinstance(v, int) else 0

    def _entry_only(self, index: int) -> Entry | None:
        """The entry of ``index`` subindex 0 (None: not in the OD)."""
        hit = self._entry(index, 0)
        return hit[0] if hit is not None else None

    def _controls(self) -> tuple[Entry | None, ...]:
        """The entries of CONTROLS, looked up once."""
        hits = self._control_hits
        if hits is None:
            hits = self._control_hits = tuple([self._entry_only(i) for i in CONTROLS])
        return hits

    def _bind(self) -> None:
        """The entries of CONTROLS and SNAPSHOT into their fields (looked up once: the
        OD's entries are fixed objects, only their values change)."""
        c = self._controls()
        self._c_6040, self._c_6060, self._c_607a = c[0], c[1], c[2]
        hits = self._snapshot_hits
        if hits is None:
            hits = self._snapshot_hits = tuple([self._entry_only(i) for i in SNAPSHOT])
        self._s_60ff, self._s_6083, self._s_6084, self._s_607a = hits[0], hits[1], hits[2], hits[3]
        self._s_60b0, self._s_60b1, self._s_6071, self._s_60b2 = hits[4], hits[5], hits[6], hits[7]
        self._s_6065, self._s_6085, self._s_605a = hits[8], hits[9], hits[10]
        self._bound = True

    def _set(self, index: int, value: int, sub: int = 0) -> None:
        hit = self._entry(index, sub)
        if hit is not None:
            e, lo, hi = hit
            v = int(value)
            e.value = lo if v < lo else hi if v > hi else v

    # ----------------------------------------------------------------- published values
    def pub_flush(self) -> None:
        """Write the values _publish() kept into their OD entries, if they wait for them:
        whatever reads the OD (the OD's own accessors, SDO, the control socket, the
        trace) sees the values of the last update, as if they had been written then (P38)."""
        if not self.pub_pending:
            return
        self.pub_pending = False
        hits = self._published
        assert hits is not None
        for k in range(len(hits)):
            hit = hits[k]
            if hit is not None:
                e = hit[0]
                e.value = self.pub_values[k]

    def tx_slots(self, entries: tuple[Entry, ...]) -> tuple[int, ...] | None:
        """For each entry of a TxPDO image, its index in ``pub_values`` (-1: not one the
        drive publishes), or None if the drive keeps no value as a C integer (P38)."""
        hits = self._published
        if hits is None or not self._pub_c:
            return None
        slots = []
        for e in entries:
            slot = -1
            for k in range(len(hits)):
                hit = hits[k]
                if hit is not None and hit[0] is e:
                    slot = k
            slots.append(slot)
        return tuple(slots)

    def _publish_hits(self) -> tuple[tuple[Entry, int, int] | None, ...]:
        """The PUBLISHED entries, looked up once, with their ranges as C integers where
        every range fits one (``_pub_c``, P34)."""
        hits = self._published = tuple([self._entry(i, 0) for i in PUBLISHED])
        ranges = [(h[1], h[2]) if h is not None else (0, 0) for h in hits]
        self._pub_c = all(lo >= -(1 << 63) and hi < 1 << 63 for lo, hi in ranges)
        if self._pub_c:
            self._pub_lo = [lo for lo, _ in ranges]
            self._pub_hi = [hi for _, hi in ranges]
            self.pub_values = array("q", [0] * len(hits))
        return hits
