"""Type stub of the daemon's compiled responder (ecatsim/responder.pyx, decision P9)."""

from ecatsim.segment import Segment

TIMEOUT: int
WAKE: int
FRAME: int
REPLIED: int
DROPPED: int

class SegmentError(Exception):
    """Segment.pulses_due or Segment.process raised on a frame (its ``__cause__``);
    ``args[0]``: the frame's length."""

def serve(
    fd: int,
    others: tuple[int, ...],
    buf: bytearray,
    rx_copy: bytearray,
    deadline_ns: int,
    busy: bool,
    seg: Segment | None,
    t_rx: int,
    timer_fd: int,
) -> tuple[int, int, int]: ...
def timer() -> int: ...
