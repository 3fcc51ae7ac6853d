"""Type stub of the daemon's compiled responder (ecatsim/ethercat/responder.pyx, decision P9)."""

from collections.abc import Callable

from ecatsim.ethercat.recorder import FrameRecorder
from ecatsim.ethercat.sequence import FrameSequence

TIMEOUT: int
WAKE: int
FRAME: int
REPLIED: int
DROPPED: int

class SegmentError(Exception):
    """Schedule.pulses_due or Segment.process raised on a frame (its ``__cause__``);
    ``args[0]``: the frame's length."""

class ServiceError(Exception):
    """Segment.after_reply or Segment.service raised (its ``__cause__``); ``args``:
    ("process" or "service", the time it ran for, serve()'s code before it)."""

class Responder:
    busy: bool
    replied: int
    entry: int
    reply_max_ns: int
    replies_over_1ms: int
    replies_over_2ms: int
    pickup_max_ns: int
    late_picked_up_late: int
    def __init__(
        self,
        fd: int,
        others: tuple[int, ...],
        recorder: FrameRecorder,
        busy: bool = False,
        timer: bool = True,
        out_fd: int = -1,
    ) -> None: ...
    def set_follow(self, follow: Callable[[int], int] | None, fd: int, look_ns: int) -> None: ...
    def serve(
        self,
        buf: bytearray,
        deadline_ns: int,
        seq: FrameSequence | None = None,
        t_rx: int = 0,
        timers: bool = False,
    ) -> tuple[int, int, int]: ...
    def reply_times(self) -> dict[str, int]: ...
    def frame_waiting(self) -> bool: ...
    def close(self) -> None: ...
