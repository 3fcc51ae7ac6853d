"""The frame context: the per-segment state every ESC of a segment shares while a frame
passes (the frame's number and times, the dirty flags the segment reads after the walk,
the raised PDI interrupt lines). Ref: ETG.1000.4 §5.3 (a frame passes every slave).
"""

from __future__ import annotations

#: "no deadline" in the comparisons of host times (later than any)
NO_DEADLINE = 1 << 62


class FrameContext:
    """Per-segment state shared by all ESCs: the frame being processed and dirty flags."""

    __slots__ = (
        "addr_dirty",
        "flush",
        "frame_no",
        "irq_dirty",
        "latch_wait",
        "logical_dirty",
        "n_raised",
        "pdi_ns",
        "raised",
        "t_ns",
        "timers_dirty",
        "topology_dirty",
        "wd_next",
    )

    def __init__(self) -> None:
        self.frame_no = 0
        self.t_ns = 0
        #: host time of the PDI work in progress (the firmware's service, a PDI access):
        #: the time base of PDI-side DC event times (0x09F8, 0x09FC) and activations
        self.pdi_ns = 0
        self.irq_dirty = True
        self.addr_dirty = True
        self.logical_dirty = True
        self.topology_dirty = True
        #: an ESC waits for a frame entering at a port that leads out of the process, to
        #: latch its receive time (DcUnit.latch_wait)
        self.latch_wait = False
        self.timers_dirty = True
        #: no process-data watchdog of the segment expires before this host time: lowered
        #: by every ``Watchdog.trigger`` that sets an earlier deadline, made exact again by
        #: the schedule's scan of the watchdogs once it falls due (decision P100)
        self.wd_next = NO_DEADLINE
        #: ESCs whose PDI interrupt line (AL event & mask) is raised: a byte per position
        #: and their number, C fields kept by ``Esc._pdi_irq`` (P43); ``pending``: the set
        self.raised = bytearray()
        self.n_raised = 0
        #: positions of ESCs with an EEPROM image to persist
        self.flush: set[int] = set()

    @property
    def pending(self) -> set[int]:
        """Positions of the ESCs whose PDI interrupt line is raised."""
        return {i for i, v in enumerate(self.raised) if v} if self.n_raised else set()

    def set_raised(self, position: int, line: bool) -> None:
        """Record the PDI interrupt line of the ESC at ``position`` (``Esc._pdi_irq``)."""
        r = self.raised
        if position >= len(r):
            r.extend(bytes(position + 1 - len(r)))
        v = 1 if line else 0
        self.n_raised += v - r[position]
        r[position] = v
