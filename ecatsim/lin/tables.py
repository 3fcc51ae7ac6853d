"""The TMC211 datasheet's tables as data: velocities, accelerations, currents, step modes,
commands, ROM pointers and the Table 8 priority encoder.

Velocities are kept in the unit of the 16-bit position registers, 1/16 micro-steps
(TMC211 §7.3 FAQ "Which units, formats and ranges does position information have?"):
one full step is 16 units.
"""

from __future__ import annotations

from enum import Enum, IntEnum

#: 16-bit position units (1/16 micro-steps) per full step (TMC211 §7.3)
UNITS_PER_FULL_STEP = 16

# --- TMC211 §5.1.4 Table 3: Vmax parameter --------------------------------------------

#: Vmax [FS/s] by Vmax index (Table 3, column "Vmax [FS/s]")
VMAX_FS: tuple[int, ...] = (99, 136, 167, 197, 213, 228, 243, 273, 303, 334, 364, 395, 456,
                            546, 729, 973)  # fmt: skip
#: Vmax in half-steps/s (Table 3, column "Half-Step Mode")
VMAX_HALF: tuple[int, ...] = (197, 273, 334, 395, 425, 456, 486, 546, 607, 668, 729, 790, 912,
                              1091, 1457, 1945)  # fmt: skip
#: Vmax in 1/4 micro-steps/s (Table 3)
VMAX_QUARTER: tuple[int, ...] = (395, 546, 668, 790, 851, 912, 973, 1091, 1213, 1335, 1457,
                                 1579, 1823, 2182, 2914, 3891)  # fmt: skip
#: Vmax in 1/8 micro-steps/s (Table 3)
VMAX_EIGHTH: tuple[int, ...] = (790, 1091, 1335, 1579, 1701, 1823, 1945, 2182, 2426, 2670, 2914,
                                3159, 3647, 4364, 5829, 7782)  # fmt: skip
#: Vmax in 1/16 micro-steps/s (Table 3): the velocity the ramp generator runs at, in
#: position units per second (the most precise column of the table)
VMAX_SIXTEENTH: tuple[int, ...] = (1579, 2182, 2670, 3159, 3403, 3647, 3891, 4364, 4852, 5341,
                                   5829, 6317, 7294, 8728, 11658, 15564)  # fmt: skip
#: Vmax groups (§5.1.4 and §7.3 FAQ "Is it possible to change Vmax on-the-fly?")
VMAX_GROUP: str = "ABBBBBBCCCCCCDDD"

# --- TMC211 §5.1.5 Table 4: Vmin [FS/s] by Vmin index (rows 1..15) and Vmax index ---------
#: row 0 is "Vmin = Vmax" (factor 1): see :func:`vmin_units`
VMIN_FS: tuple[tuple[int, ...], ...] = (
    (3, 4, 5, 6, 6, 7, 7, 8, 8, 10, 10, 11, 13, 15, 19, 26),
    (6, 8, 10, 11, 12, 13, 14, 15, 17, 19, 21, 23, 27, 30, 42, 57),
    (9, 12, 15, 18, 19, 21, 22, 25, 27, 30, 32, 36, 42, 50, 65, 88),
    (12, 16, 20, 24, 26, 28, 30, 32, 36, 40, 44, 48, 55, 65, 88, 118),
    (15, 21, 26, 30, 32, 35, 37, 42, 46, 52, 55, 61, 71, 84, 111, 149),
    (18, 25, 30, 36, 39, 42, 45, 50, 55, 61, 67, 72, 84, 99, 134, 179),
    (22, 30, 36, 43, 46, 50, 52, 59, 65, 72, 78, 86, 99, 118, 156, 210),
    (24, 33, 41, 49, 52, 56, 60, 67, 74, 82, 90, 97, 112, 134, 179, 240),
    (28, 38, 47, 55, 59, 64, 68, 76, 84, 94, 101, 111, 128, 153, 202, 271),
    (30, 42, 52, 61, 66, 71, 75, 84, 94, 103, 112, 122, 141, 168, 225, 301),
    (34, 47, 57, 68, 72, 78, 83, 94, 103, 114, 124, 135, 156, 187, 248, 332),
    (37, 50, 62, 73, 79, 85, 91, 101, 112, 124, 135, 147, 170, 202, 271, 362),
    (40, 55, 68, 80, 86, 92, 98, 111, 122, 135, 147, 160, 185, 221, 294, 393),
    (43, 59, 72, 86, 92, 99, 106, 118, 132, 145, 158, 172, 198, 236, 317, 423),
    (46, 64, 78, 92, 99, 107, 114, 128, 141, 156, 170, 185, 214, 256, 340, 454),
)

# --- TMC211 §5.1.6 Table 5: Acc [FS/s²] by Acc index and Vmax index -----------------------
# The table's layout is partly lost in the source; how its merged cells are read is
# decision N3 (docs/decisions.md).


def _row(*spans: tuple[int, int]) -> tuple[int, ...]:
    """A row of 16 values from (value, number of Vmax columns) spans."""
    out: list[int] = []
    for value, n in spans:
        out += [value] * n
    assert len(out) == 16
    return tuple(out)


ACC_FS2: tuple[tuple[int, ...], ...] = (
    _row((49, 13), (106, 1), (473, 2)),
    _row((218, 14), (735, 2)),
    _row((1004, 16)),
    _row((3609, 16)),
    _row((6228, 16)),
    _row((8848, 16)),
    _row((11409, 16)),
    _row((13970, 16)),
    _row((16531, 16)),
    _row((19092, 16)),
    _row((21886, 16)),
    _row((21886, 1), (24447, 15)),
    _row((21886, 1), (24447, 15)),
    _row((21886, 1), (29570, 15)),
    _row((21886, 1), (29570, 6), (34925, 9)),
    _row((21886, 1), (29570, 6), (40047, 9)),
)

# --- TMC211 §5.3.2 Table 12: Irun / Ihold settings ----------------------------------------
#: peak coil current [mA] by Irun/Ihold setting
CURRENT_MA: tuple[int, ...] = (59, 71, 84, 100, 119, 141, 168, 200, 238, 283, 336, 400, 476, 566,
                               673, 800)  # fmt: skip

# --- TMC211 §5.3 Table 11: StepMode; §5.1.7 Table 6; §7.3 FAQ -----------------------------


class StepMode(IntEnum):
    """StepMode[1:0] (Table 11)."""

    HALF = 0
    QUARTER = 1
    EIGHTH = 2
    SIXTEENTH = 3


#: LSB of the 16-bit position fields in each step mode (§7.3 FAQ: bit 3 for 1/2, bit 2 for
#: 1/4, bit 1 for 1/8, bit 0 for 1/16 micro-stepping), in position units
STEP_RESOLUTION: dict[StepMode, int] = {
    StepMode.HALF: 8,
    StepMode.QUARTER: 4,
    StepMode.EIGHTH: 2,
    StepMode.SIXTEENTH: 1,
}

#: SecPos[10:0] value that disables the secure position (§5.1.8, §6.11.5: 0x400 = -1024)
SECPOS_DISABLED = 0x400


def vmax_units(vmax: int) -> float:
    """Vmax in position units per second (Table 3, 1/16 micro-stepping column)."""
    return float(VMAX_SIXTEENTH[vmax])


def vmin_units(vmin: int, vmax: int) -> float:
    """Vmin in position units per second (Table 4; index 0 is Vmin = Vmax)."""
    if vmin == 0:
        return vmax_units(vmax)
    return float(VMIN_FS[vmin - 1][vmax] * UNITS_PER_FULL_STEP)


def acc_units(acc: int, vmax: int) -> float:
    """Acceleration in position units per second² (Table 5)."""
    return float(ACC_FS2[acc][vmax] * UNITS_PER_FULL_STEP)


# --- TMC211 §6.8 Table 15: commands and ROM pointers ------------------------------------


class Cmd(IntEnum):
    """Command byte CMD[6:0] (Table 15)."""

    GET_ACTUAL_POS = 0x00
    GET_FULL_STATUS = 0x01
    GET_OTP_PARAM = 0x02
    GET_STATUS = 0x03
    GOTO_SECURE_POSITION = 0x04
    HARD_STOP = 0x05
    RESET_POSITION = 0x06
    RESET_TO_DEFAULT = 0x07
    RUN_INIT = 0x08
    SET_MOTOR_PARAM = 0x09
    SET_POSITION = 0x0B
    SET_POSITION_SHORT_1 = 0x0C
    SET_POSITION_SHORT_2 = 0x0D
    SET_POSITION_SHORT_4 = 0x0E
    SOFT_STOP = 0x0F
    SET_OTP_PARAM = 0x10
    DYNAMIC_ID = 0x11


class RomPointer(IntEnum):
    """ROM pointers linking a dynamic identifier to a frame (Table 15)."""

    GENERAL_PURPOSE_2 = 0b0000
    GENERAL_PURPOSE_4 = 0b0001
    GET_ACTUAL_POS = 0b0010
    GET_STATUS = 0b0011
    SET_POSITION = 0b0100
    SET_POSITION_SHORT_1 = 0b0101
    SET_POSITION_SHORT_2 = 0b0110
    SET_POSITION_SHORT_4 = 0b0111
    PREPARING = 0b1000


#: data bytes of the frame behind each ROM pointer (§6.9, §6.11); the dynamic identifier
#: must code this length (decision N10)
ROM_FRAME_LENGTH: dict[RomPointer, int] = {
    RomPointer.GENERAL_PURPOSE_2: 2,
    RomPointer.GENERAL_PURPOSE_4: 4,
    RomPointer.GET_ACTUAL_POS: 4,
    RomPointer.GET_STATUS: 2,
    RomPointer.SET_POSITION: 2,
    RomPointer.SET_POSITION_SHORT_1: 2,
    RomPointer.SET_POSITION_SHORT_2: 4,
    RomPointer.SET_POSITION_SHORT_4: 8,
    RomPointer.PREPARING: 2,
}
#: the ROM pointers whose frames the node publishes (reading frames type #5)
PUBLISHED: frozenset[RomPointer] = frozenset({RomPointer.GET_ACTUAL_POS, RomPointer.GET_STATUS})
#: the example dynamic identifiers of Table 15 (xxx = 000); the shipped LDF uses them
EXAMPLE_IDS: dict[RomPointer, int] = {
    RomPointer.GET_ACTUAL_POS: 0b100000,
    RomPointer.GET_STATUS: 0b000000,
    RomPointer.SET_POSITION: 0b010000,
    RomPointer.SET_POSITION_SHORT_1: 0b001001,
    RomPointer.SET_POSITION_SHORT_2: 0b101001,
    RomPointer.SET_POSITION_SHORT_4: 0b111001,
    RomPointer.GENERAL_PURPOSE_2: 0b011000,
    RomPointer.GENERAL_PURPOSE_4: 0b101000,
    RomPointer.PREPARING: 0b011010,
}

#: commands a general-purpose writing frame (type #1) carries (§6.11.5-6.11.8, 6.11.12,
#: 6.11.14)
GENERAL_PURPOSE_COMMANDS: frozenset[int] = frozenset(
    {
        Cmd.GOTO_SECURE_POSITION,
        Cmd.HARD_STOP,
        Cmd.RESET_POSITION,
        Cmd.RESET_TO_DEFAULT,
        Cmd.SOFT_STOP,
        Cmd.SET_POSITION,
    }
)
#: commands a preparing frame (type #7/#8) prepares for the 0x3D reading frame (§6.11.1-3)
PREPARABLE: frozenset[int] = frozenset({Cmd.GET_ACTUAL_POS, Cmd.GET_FULL_STATUS, Cmd.GET_OTP_PARAM})

# --- TMC211 §5.1.15 Table 8: priority encoder -------------------------------------------


class State(Enum):
    """The states of Table 8 (columns)."""

    STOPPED = "Stopped"
    GOTOPOS = "GotoPos"
    RUNINIT = "RunInit"
    SOFTSTOP = "SoftStop"
    HARDSTOP = "HardStop"
    SHUTDOWN = "ShutDown"
    SLEEP = "Sleep"


class Event(Enum):
    """The rows of Table 8: commands and internal events."""

    GET_ACTUAL_POS = "GetActualPos"
    GET_OTP_PARAM = "GetOTPParam"
    GET_STATUS = "GetFullStatus or GetStatus"
    RESET_TO_DEFAULT = "ResetToDefault"
    SET_MOTOR_PARAM = "SetMotorParam"
    RESET_POSITION = "ResetPosition"
    SET_POSITION = "SetPosition"
    SET_POSITION_SHORT = "SetPositionShort"
    GOTO_SECURE_POSITION = "GotoSecurePosition"
    RUN_INIT = "RunInit"
    HARD_STOP = "HardStop"
    SOFT_STOP = "SoftStop"
    SLEEP = "Sleep or LIN timeout"
    ELECTRICAL = "HardStop (CPFail, UV2 or ElDef)"
    THERMAL = "Thermal shutdown"
    MOTION_FINISHED = "Motion finished"


class Action(Enum):
    """The cells of Table 8."""

    IGNORED = "command ignored"
    NA = "n.a."
    RESPOND = "LIN in-frame response"
    OTP_REFRESH_RESPOND = "OTP refresh; LIN in-frame response"
    STATUS_RESPOND = "LIN in-frame response; attempt to clear flags"
    STATUS_LEAVE_SHUTDOWN = "LIN in-frame response; if <TSD> and <HS> are clear then → Stopped"
    RESET_TO_DEFAULT = "OTP refresh; OTP to RAM; AccShape reset"
    RAM_UPDATE = "RAM update"
    RESET_POSITION = "TagPos and ActPos reset"
    TAGPOS_GOTO = "TagPos updated; → GotoPos"
    TAGPOS = "TagPos updated"
    SECPOS_GOTO = "if <SecEn> then TagPos = SecPos; → GotoPos"
    SECPOS = "if <SecEn> then TagPos = SecPos"
    TO_RUNINIT = "→ RunInit"
    TO_HARDSTOP_STEPLOSS = "→ HardStop; <StepLoss> = 1"
    TO_SOFTSTOP = "→ SoftStop"
    SLEEP_STOPPED = "see note 9"
    SLEEP_GOTOPOS = "if <SecEn> then TagPos = SecPos else → SoftStop"
    SLEEP_RUNINIT = "if <SecEn> then TagPos = SecPos, evaluated after RunInit"
    SLEEP_WHEN_STOPPED = "no action; <Sleep> evaluated when the motor stops"
    TO_SLEEP = "→ Sleep"
    TO_SHUTDOWN = "→ Shutdown"
    TO_HARDSTOP = "→ HardStop"
    TO_STOPPED = "→ Stopped"
    TO_STOPPED_KEEP = "→ Stopped; TagPos = ActPos"


def _cells(*cells: Action) -> dict[State, Action]:
    return dict(zip(State, cells, strict=True))


_I, _NA = Action.IGNORED, Action.NA

#: Table 8 (TMC211 §5.1.15): what each command or internal event does in each state.
#: Columns: Stopped, GotoPos, RunInit, SoftStop, HardStop, ShutDown, Sleep. Blank cells are
#: "command ignored"; the Sleep column is blank: the circuit has no power (note 1)
PRIORITY_ENCODER: dict[Event, dict[State, Action]] = {
    Event.GET_ACTUAL_POS: _cells(*[Action.RESPOND] * 6, _I),
    Event.GET_OTP_PARAM: _cells(*[Action.OTP_REFRESH_RESPOND] * 6, _I),
    Event.GET_STATUS: _cells(*[Action.STATUS_RESPOND] * 5, Action.STATUS_LEAVE_SHUTDOWN, _I),
    Event.RESET_TO_DEFAULT: _cells(*[Action.RESET_TO_DEFAULT] * 6, _I),
    Event.SET_MOTOR_PARAM: _cells(*[Action.RAM_UPDATE] * 6, _I),
    Event.RESET_POSITION: _cells(Action.RESET_POSITION, _I, _I, _I, _I, Action.RESET_POSITION, _I),
    Event.SET_POSITION: _cells(Action.TAGPOS_GOTO, Action.TAGPOS, Action.TAGPOS, _I, _I, _I, _I),
    Event.SET_POSITION_SHORT: _cells(
        Action.TAGPOS_GOTO, Action.TAGPOS, Action.TAGPOS, _I, _I, _I, _I
    ),
    Event.GOTO_SECURE_POSITION: _cells(
        Action.SECPOS_GOTO, Action.SECPOS, Action.SECPOS, _I, _I, _I, _I
    ),
    Event.RUN_INIT: _cells(Action.TO_RUNINIT, _I, _I, _I, _I, _I, _I),
    Event.HARD_STOP: _cells(_I, *[Action.TO_HARDSTOP_STEPLOSS] * 3, _I, _I, _I),
    Event.SOFT_STOP: _cells(_I, Action.TO_SOFTSTOP, _I, _I, _I, _I, _I),
    Event.SLEEP: _cells(
        Action.SLEEP_STOPPED,
        Action.SLEEP_GOTOPOS,
        Action.SLEEP_RUNINIT,
        Action.SLEEP_WHEN_STOPPED,
        Action.SLEEP_WHEN_STOPPED,
        Action.TO_SLEEP,
        _I,
    ),
    Event.ELECTRICAL: _cells(Action.TO_SHUTDOWN, *[Action.TO_HARDSTOP] * 3, _I, _I, _I),
    Event.THERMAL: _cells(
        Action.TO_SHUTDOWN, Action.TO_SOFTSTOP, Action.TO_SOFTSTOP, _I, _I, _I, _I
    ),
    Event.MOTION_FINISHED: _cells(
        _NA,
        Action.TO_STOPPED,
        Action.TO_STOPPED,
        Action.TO_STOPPED_KEEP,
        Action.TO_STOPPED_KEEP,
        _NA,
        _NA,
    ),
}

#: internal events in the order the encoder weighs them when they coincide (§5.1.15: the
#: HardStop has the highest priority, "Motion finished" the lowest)
INTERNAL_PRIORITY: tuple[Event, ...] = (Event.ELECTRICAL, Event.THERMAL, Event.MOTION_FINISHED)

#: the Table 8 row of each command byte
COMMAND_EVENT: dict[int, Event] = {
    Cmd.GET_ACTUAL_POS: Event.GET_ACTUAL_POS,
    Cmd.GET_FULL_STATUS: Event.GET_STATUS,
    Cmd.GET_OTP_PARAM: Event.GET_OTP_PARAM,
    Cmd.GET_STATUS: Event.GET_STATUS,
    Cmd.GOTO_SECURE_POSITION: Event.GOTO_SECURE_POSITION,
    Cmd.HARD_STOP: Event.HARD_STOP,
    Cmd.RESET_POSITION: Event.RESET_POSITION,
    Cmd.RESET_TO_DEFAULT: Event.RESET_TO_DEFAULT,
    Cmd.RUN_INIT: Event.RUN_INIT,
    Cmd.SET_MOTOR_PARAM: Event.SET_MOTOR_PARAM,
    Cmd.SET_POSITION: Event.SET_POSITION,
    Cmd.SET_POSITION_SHORT_1: Event.SET_POSITION_SHORT,
    Cmd.SET_POSITION_SHORT_2: Event.SET_POSITION_SHORT,
    Cmd.SET_POSITION_SHORT_4: Event.SET_POSITION_SHORT,
    Cmd.SOFT_STOP: Event.SOFT_STOP,
}

# --- Temperature and battery thresholds (TMC211 §10.3 Tables 24, 25) --------------------

#: thermal warning Ttw [°C] (Table 24, typ.)
T_WARNING_C = 145.0
#: thermal shutdown Ttsd = Ttw + 10 [°C] (Table 24)
T_SHUTDOWN_C = 155.0
#: low temperature warning Tlow = Ttw - 155 [°C] (Table 24)
T_LOW_C = -10.0
#: stop voltage UV2 [V] (Table 25, typ.)
UV2_V = 8.5
#: low voltage warning UV1 [V] (Table 25, typ.)
UV1_V = 9.4
