"""Type stub of the compiled DC loops (ecatsim/esc/_dcloop.c)."""

from typing import Any

MOVE_NS: int
FAR_NS: int
DC_SYSTEM_TIME: int
DC_SYSTEM_TIME_OFFSET: int
DC_SYSTEM_TIME_DELAY: int
DC_SYSTEM_TIME_DIFF: int
DC_SPEED_COUNTER_START: int
SYNC_LATCH_CONFIG: int
DC_START_TIME: int
DC_SYNC0_CYCLE: int
DC_ACTIVATION: int
DC_ACTIVATION_STATUS: int
DC_SYNC0_STATUS: int
AL_EVENT_REQUEST: int
AL_EVENT_MASK: int
EV_SYNC0: int
MAX_SYNC0_CATCHUP: int
PULSE_HINT_MARGIN_NS: int
NO_DEADLINE: int

def time_loops(seg: Any, hook: Any) -> bool: ...
def pulses(seg: Any, t: int, esc_type: type, dc_type: type) -> bool: ...
