"""Type stub of the compiled responder (ecatsim/_serve.c)."""

from ecatsim.segment import Segment

TIMEOUT: int
WAKE: int
FRAME: int
REPLIED: int
RESUME: int

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
    /,
) -> tuple[int, int, int, int]: ...
def timer() -> int: ...
def slot_offset(obj: object, name: str, /) -> int: ...
