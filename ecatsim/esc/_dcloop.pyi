"""Type stub of the compiled DC time loops (ecatsim/esc/_dcloop.c)."""

from typing import Any

MOVE_NS: int
FAR_NS: int
DC_SYSTEM_TIME: int
DC_SYSTEM_TIME_OFFSET: int
DC_SYSTEM_TIME_DELAY: int
DC_SYSTEM_TIME_DIFF: int
DC_SPEED_COUNTER_START: int

def time_loops(seg: Any, hook: Any) -> bool: ...
