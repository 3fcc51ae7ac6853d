"""The per-frame sequence, written once (decision P21): what happens to a frame between
its receipt and the next wait, for the compiled responder (ecatsim/ethercat/responder.pyx, which
keeps only the system calls: wait, receive, send) and the daemon's Python loop
(``Daemon.handle_frame``) alike.

1. :meth:`FrameSequence.arrive`: the EtherCAT header is found (else ``NOT_ECAT``: not for
   the segment), the frame is kept in the recorder as received, the SYNC pulses due before
   its arrival fire (each at its own time), the segment walks it, the processed bit is set:
   ``REPLY`` (the caller sends ``buf[:n]``) or ``DROPPED`` (destroyed, no reply).
2. The caller sends the reply.
3. :meth:`after`: the work the frame left for after its reply (the DC time loops, P7).
4. :meth:`service`: the firmware and the timers due by the frame's arrival; the firmware's
   work stops for a frame that waits and goes on after that frame's reply (P19).

Compiled with the core (``sequence.pxd``): every call here is a C call, and the frame is
read through one typed view per buffer (made when the buffer changes, as the segment's).
Ref: docs/architecture.md "Frame path"; ETG.1000.4 §5.3-5.4.
"""

from __future__ import annotations

from ecatsim.ethercat.recorder import FrameRecorder
from ecatsim.ethercat.segment import Segment
from ecatsim.wire.frame import ecat_offset, mark_processed

#: arrive()'s results
NOT_ECAT = 0
DROPPED = 1
REPLY = 2
#: the same as C constants of the compiled core (a constant declared in the .pxd is not
#: visible to Python importers, decision P13)
_NOT_ECAT = NOT_ECAT
_DROPPED = DROPPED
_REPLY = REPLY


class FrameSequence:
    """One segment's per-frame sequence; ``ethernet``: frames carry an Ethernet header
    (every link but UDP)."""

    __slots__ = ("_buf", "_view", "ethernet", "off", "recorder", "segment")

    def __init__(self, segment: Segment, recorder: FrameRecorder, ethernet: bool = True) -> None:
        self.segment = segment
        self.recorder = recorder
        self.ethernet = ethernet
        #: where the EtherCAT header of the last frame that arrived starts
        self.off = 0
        self._buf: bytearray | None = None
        self._view = memoryview(bytearray())

    def arrive(self, buf: bytearray, n: int, t_rx: int, entry: int = 0) -> int:
        """Steps 1 of the sequence for the frame in ``buf[:n]``, received at host time
        ``t_rx`` on the daemon's link (``entry`` 0) or the out link (1): NOT_ECAT, DROPPED
        or REPLY (see the module's docstring). Only a frame that passed a processing unit
        gets the processed bit (decision L4); ``segment.exit`` says where it leaves."""
        if buf is not self._buf:
            self._view = memoryview(buf)
            self._buf = buf
        view = self._view
        off = ecat_offset(view, n, self.ethernet)
        if off < 0:
            return _NOT_ECAT
        self.recorder.record(view, n)  # as received, before the walk patches it
        seg = self.segment
        seg.schedule.pulses_due(t_rx)  # pulses due before this frame arrived come first
        if not seg.process(buf, off, n, t_rx, entry):
            return _DROPPED
        if self.ethernet and seg.processed:
            mark_processed(view)
        self.off = off
        return _REPLY

    def after(self) -> None:
        """Step 3: the work the frame left for after its reply (decision P7)."""
        self.segment.after_reply()

    def service(self, t: int) -> None:
        """Step 4: the firmware and the timers due by ``t`` (decision P19)."""
        self.segment.service_at(t)

    def release(self) -> None:
        """Let go of the last buffer's view (the caller may resize it again)."""
        self._buf = None
        self._view = memoryview(bytearray())
