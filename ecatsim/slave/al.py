"""The EtherCAT application-layer state machine as a transition table.

States and transition names follow ETG.1000.6 §6.4.1 (Table 9 "State transitions and
local management services"): IP, PI, PS, SP, SO, OS, OP, OI, SI, IB, BI. A request that is
not in the table is refused with 0x0011 (invalid requested state change); an undefined
state code with 0x0012 (unknown requested state).
"""

from __future__ import annotations

from enum import IntEnum


class AlState(IntEnum):
    """AL states as coded in AL control/status bits 3:0. Ref: TMC8460 §5.20 Table 32."""

    INIT = 1
    PREOP = 2
    BOOT = 3
    SAFEOP = 4
    OP = 8


class Transition(IntEnum):
    """Named transitions of ETG.1000.6 §6.4.1 Table 9."""

    IP = 1  # INIT -> PREOP: start mailbox
    PI = 2  # PREOP -> INIT: stop mailbox
    PS = 3  # PREOP -> SAFEOP: start inputs
    SP = 4  # SAFEOP -> PREOP: stop inputs
    SO = 5  # SAFEOP -> OP: start outputs
    OS = 6  # OP -> SAFEOP: stop outputs
    OP = 7  # OP -> PREOP: stop outputs and inputs
    OI = 8  # OP -> INIT: stop outputs, inputs, mailbox
    SI = 9  # SAFEOP -> INIT: stop inputs, mailbox
    IB = 10  # INIT -> BOOT: start bootstrap mailbox
    BI = 11  # BOOT -> INIT: stop bootstrap mailbox


#: (current, requested) -> transition. Everything else is 0x0011 (or a no-op for the same
#: state). Ref: ETG.1000.6 §6.4.1 Table 9 and Figure 13.
TRANSITIONS: dict[tuple[AlState, AlState], Transition] = {
    (AlState.INIT, AlState.PREOP): Transition.IP,
    (AlState.PREOP, AlState.INIT): Transition.PI,
    (AlState.PREOP, AlState.SAFEOP): Transition.PS,
    (AlState.SAFEOP, AlState.PREOP): Transition.SP,
    (AlState.SAFEOP, AlState.OP): Transition.SO,
    (AlState.OP, AlState.SAFEOP): Transition.OS,
    (AlState.OP, AlState.PREOP): Transition.OP,
    (AlState.OP, AlState.INIT): Transition.OI,
    (AlState.SAFEOP, AlState.INIT): Transition.SI,
    (AlState.INIT, AlState.BOOT): Transition.IB,
    (AlState.BOOT, AlState.INIT): Transition.BI,
}

#: Order used to decide whether a request goes "down" (allowed while an error is
#: unacknowledged). BOOT ranks with PREOP: it is left only towards INIT.
RANK = {AlState.INIT: 0, AlState.PREOP: 1, AlState.BOOT: 1, AlState.SAFEOP: 2, AlState.OP: 3}

AL_STATE_MASK = 0x0F
AL_ERROR = 0x10
AL_ID = 0x20

# AL status codes used by the state machine. Ref: ETG.1000.6 Table 11.
CODE_NONE = 0x0000
CODE_INVALID_STATE_CHANGE = 0x0011
CODE_UNKNOWN_STATE = 0x0012
CODE_BOOTSTRAP_NOT_SUPPORTED = 0x0013
CODE_INVALID_MBX_BOOT = 0x0015
CODE_INVALID_MBX_PREOP = 0x0016
CODE_SM_WATCHDOG = 0x001B
CODE_INVALID_OUTPUT_CONFIG = 0x001D
CODE_INVALID_INPUT_CONFIG = 0x001E

#: the meaning of every AL status code (0x0134). Ref: ETG.1000.6 Table 11.
AL_STATUS_CODE_TEXT: dict[int, str] = {
    0x0000: "no error",
    0x0001: "unspecified error",
    0x0002: "no memory",
    0x0011: "invalid requested state change",
    0x0012: "unknown requested state",
    0x0013: "bootstrap not supported",
    0x0014: "no valid firmware",
    0x0015: "invalid mailbox configuration (BOOT)",
    0x0016: "invalid mailbox configuration (PREOP)",
    0x0017: "invalid sync manager configuration",
    0x0018: "no valid inputs available",
    0x0019: "no valid outputs",
    0x001A: "synchronization error",
    0x001B: "sync manager watchdog",
    0x001C: "invalid sync manager types",
    0x001D: "invalid output configuration",
    0x001E: "invalid input configuration",
    0x001F: "invalid watchdog configuration",
    0x0020: "slave needs cold start",
    0x0021: "slave needs INIT",
    0x0022: "slave needs PREOP",
    0x0023: "slave needs SAFEOP",
    0x0024: "invalid input mapping",
    0x0025: "invalid output mapping",
    0x0026: "inconsistent settings",
    0x0027: "freerun not supported",
    0x0028: "synchronization not supported",
    0x0029: "freerun needs 3-buffer mode",
    0x002A: "background watchdog",
    0x002B: "no valid inputs and outputs",
    0x002C: "fatal sync error",
    0x002D: "no sync error",
    0x0030: "invalid DC SYNC configuration",
    0x0031: "invalid DC latch configuration",
    0x0032: "PLL error",
    0x0033: "DC sync IO error",
    0x0034: "DC sync timeout error",
    0x0035: "DC invalid sync cycle time",
    0x0036: "DC sync0 cycle time",
    0x0037: "DC sync1 cycle time",
    0x0041: "mailbox AoE",
    0x0042: "mailbox EoE",
    0x0043: "mailbox CoE",
    0x0044: "mailbox FoE",
    0x0045: "mailbox SoE",
    0x004F: "mailbox VoE",
    0x0050: "EEPROM no access",
    0x0051: "EEPROM error",
    0x0060: "slave restarted locally",
    0x0061: "device identification value updated",
}


def status_code_text(code: int) -> str:
    """``0x001B sync manager watchdog``: an AL status code and its meaning."""
    if code >= 0x8000:
        return f"0x{code:04X} vendor specific"
    return f"0x{code:04X} {AL_STATUS_CODE_TEXT.get(code, 'reserved')}"


def parse_state(code: int) -> AlState | None:
    """The AlState for bits 3:0 of AL control, or None for an undefined code."""
    try:
        return AlState(code & AL_STATE_MASK)
    except ValueError:
        return None


def lookup(current: AlState, requested: AlState) -> Transition | None:
    """The transition for (current, requested), or None if it is not allowed."""
    return TRANSITIONS.get((current, requested))
