"""CiA 402 power drive system (PDS) state machine as a transition table.

States, commands and the transition numbers 0-16 follow CiA 402-2 §8.1 / TMC8670 datasheet
Figure 3 and Tables 77 (command coding) and 83 (state coding).
"""

from __future__ import annotations

from enum import IntEnum


class PdsState(IntEnum):
    """PDS states. Ref: CiA 402-2 Figure 10; TMC8670 Table 83."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


class Command(IntEnum):
    """Controlword commands. Ref: TMC8670 Table 77; CiA 402-2 Table 34."""

    NONE = 0
    SHUTDOWN = 1  # xxxx x110
    SWITCH_ON = 2  # xxxx 0111 (also "disable operation")
    SWITCH_ON_ENABLE = 3  # xxxx 1111 (also "enable operation")
    DISABLE_VOLTAGE = 4  # xxxx xx0x
    QUICK_STOP = 5  # xxxx x01x
    FAULT_RESET = 6  # bit 7 0 -> 1


#: Statusword bits 0-3, 5, 6 per state. Ref: TMC8670 Table 83.
STATUS_BITS = {
    PdsState.NOT_READY_TO_SWITCH_ON: 0x0000,
    PdsState.SWITCH_ON_DISABLED: 0x0040,
    PdsState.READY_TO_SWITCH_ON: 0x0021,
    PdsState.SWITCHED_ON: 0x0023,
    PdsState.OPERATION_ENABLED: 0x0027,
    PdsState.QUICK_STOP_ACTIVE: 0x0007,
    PdsState.FAULT_REACTION_ACTIVE: 0x000F,
    PdsState.FAULT: 0x0008,
}

S = PdsState
C = Command
#: (state, command) -> (transition number, next state). Ref: CiA 402-2 Table 33.
TRANSITIONS: dict[tuple[PdsState, Command], tuple[int, PdsState]] = {
    (S.SWITCH_ON_DISABLED, C.SHUTDOWN): (2, S.READY_TO_SWITCH_ON),
    (S.READY_TO_SWITCH_ON, C.SWITCH_ON): (3, S.SWITCHED_ON),
    (S.READY_TO_SWITCH_ON, C.SWITCH_ON_ENABLE): (3, S.SWITCHED_ON),  # then 4
    (S.SWITCHED_ON, C.SWITCH_ON_ENABLE): (4, S.OPERATION_ENABLED),
    (S.OPERATION_ENABLED, C.SWITCH_ON): (5, S.SWITCHED_ON),
    (S.SWITCHED_ON, C.SHUTDOWN): (6, S.READY_TO_SWITCH_ON),
    (S.READY_TO_SWITCH_ON, C.DISABLE_VOLTAGE): (7, S.SWITCH_ON_DISABLED),
    (S.READY_TO_SWITCH_ON, C.QUICK_STOP): (7, S.SWITCH_ON_DISABLED),
    (S.OPERATION_ENABLED, C.SHUTDOWN): (8, S.READY_TO_SWITCH_ON),
    (S.OPERATION_ENABLED, C.DISABLE_VOLTAGE): (9, S.SWITCH_ON_DISABLED),
    (S.SWITCHED_ON, C.DISABLE_VOLTAGE): (10, S.SWITCH_ON_DISABLED),
    (S.SWITCHED_ON, C.QUICK_STOP): (10, S.SWITCH_ON_DISABLED),
    (S.OPERATION_ENABLED, C.QUICK_STOP): (11, S.QUICK_STOP_ACTIVE),
    (S.QUICK_STOP_ACTIVE, C.DISABLE_VOLTAGE): (12, S.SWITCH_ON_DISABLED),
    (S.FAULT, C.FAULT_RESET): (15, S.SWITCH_ON_DISABLED),
    (S.QUICK_STOP_ACTIVE, C.SWITCH_ON_ENABLE): (16, S.OPERATION_ENABLED),
}
#: Automatic transitions: 0 (power on), 1 (self test done), 12 (quick stop finished, option
#: codes 0-4), 13 (fault), 14 (fault reaction finished).
AUTO_START = (0, 1)
T_QUICK_STOP_DONE = 12
T_FAULT = 13
T_FAULT_REACTION_DONE = 14

#: Enabled: the motor is powered and follows set points. Ref: CiA 402-2 §8.1.3.
POWERED = frozenset({S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE, S.FAULT_REACTION_ACTIVE})


def decode(controlword: int, previous: int) -> Command:
    """The command in a controlword; the fault reset is the 0->1 edge of bit 7.

    Ref: TMC8670 Table 77 (bits 7, 3, 2, 1, 0).
    """
    if controlword & 0x80 and not previous & 0x80:
        return _FAULT_RESET
    if controlword & 0x80:
        return _NONE
    low = controlword & 0x0F
    if not low & 0x02:
        return _DISABLE_VOLTAGE
    if not low & 0x04:
        return _QUICK_STOP
    if low & 0x07 == 0x06:
        return _SHUTDOWN
    if low == 0x07:
        return _SWITCH_ON  # also "disable operation" from OPERATION_ENABLED
    return _SWITCH_ON_ENABLE  # 0x0F: switch on + enable operation


#: the commands as module constants (an enum's attribute lookup costs more than decode)
_NONE = Command.NONE
_SHUTDOWN = Command.SHUTDOWN
_SWITCH_ON = Command.SWITCH_ON
_SWITCH_ON_ENABLE = Command.SWITCH_ON_ENABLE
_DISABLE_VOLTAGE = Command.DISABLE_VOLTAGE
_QUICK_STOP = Command.QUICK_STOP
_FAULT_RESET = Command.FAULT_RESET


def _step_table() -> tuple[tuple[int, PdsState] | None, ...]:
    """TRANSITIONS by ``state * 8 + command``: a tuple index instead of a dict lookup
    whose key hashes two enum members through Python (Enum.__hash__) every cycle."""
    table: list[tuple[int, PdsState] | None] = [None] * (8 * 8)
    for (st, cmd), tr in TRANSITIONS.items():
        table[int(st) * 8 + int(cmd)] = tr
    return tuple(table)


#: TRANSITIONS as a table (see _step_table)
STEP_TABLE = _step_table()


def step(state: PdsState, cmd: Command) -> tuple[int, PdsState] | None:
    """The transition for (state, command), or None if the command does nothing there."""
    s = state  # the members' values: C integers in the compiled core
    c = cmd
    if not 0 <= s < 8 or not 0 <= c < 8:
        return None
    table = STEP_TABLE
    return table[s * 8 + c]
