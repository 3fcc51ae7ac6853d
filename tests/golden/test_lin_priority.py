"""The Table 8 priority encoder, state by command (TMC211 §5.1.15).

The expected outcome of every cell is transcribed here from the sheet by hand (not read
from ``tables.PRIORITY_ENCODER``); each node is put into the state, given the command, and
what it did is observed: its state, TagPos, ActPos, RAM, flags, or its answer.
"""

from __future__ import annotations

import pytest

from ecatsim.lin import codec
from ecatsim.lin.config import NodeConfig
from ecatsim.lin.motion import TICK_NS
from ecatsim.lin.node import Node
from ecatsim.lin.tables import PRIORITY_ENCODER, Action, Cmd, Event, RomPointer, State

# secure position 0x010 (enabled), Acc 0 so that a SoftStop lasts seconds
PARAMS = codec.MotorParams(irun=8, ihold=1, vmax=5, vmin=1, secpos=0x010, acc=0, stepmode=3)
OTHER = codec.MotorParams(irun=2, ihold=2, vmax=3, vmin=3, secpos=0x010, acc=1, stepmode=3)
OTP = bytes((0, 0, 0, 0x11, 0x22, 0x03, 0x00, 0x0C))
SEC = codec.secpos_units(0x010)
T0 = 1_000_000_000

STATES = [State.STOPPED, State.GOTOPOS, State.RUNINIT, State.SOFTSTOP, State.HARDSTOP,
          State.SHUTDOWN, State.SLEEP]  # fmt: skip


def node_in(state: State) -> Node:
    n = Node(NodeConfig(otp=OTP), T0)
    n.rom_ids[RomPointer.GET_STATUS] = 0x00
    n.rom_ids[RomPointer.GET_ACTUAL_POS] = 0x20
    if state == State.SHUTDOWN:
        return n
    if state == State.SLEEP:
        n.event(Event.SLEEP, T0)
        return n
    n._clear_flags(T0)  # GetStatus: ShutDown -> Stopped
    n.command(Cmd.SET_MOTOR_PARAM, codec.encode_motor_params(PARAMS), T0)
    now = T0
    if state == State.RUNINIT:
        n.command(Cmd.RUN_INIT, bytes((0x51, 0x40, 0x00, 0x30, 0x00)), now)
    elif state != State.STOPPED:
        n.command(Cmd.SET_POSITION, b"\x40\x00", now)
        now += 300_000_000
        n.advance(now)
        if state == State.SOFTSTOP:
            n.command(Cmd.SOFT_STOP, b"", now)
        elif state == State.HARDSTOP:
            n.command(Cmd.HARD_STOP, b"", now)
    assert n.state == state
    return n


# --- writing commands: (command, parameters) -> outcome by state -----------------------
# outcomes: "-" ignored; "ram" RAM update; "default" OTP to RAM; "reset" ActPos = TagPos =
# 0; "tag" TagPos updated; "tag>GotoPos" TagPos updated and GotoPos; "sec"/"sec>GotoPos"
# TagPos = SecPos; "pending" TagPos taken after RunInit; ">X" transition to state X;
# ">HardStop+StepLoss"
S, G, R, SS, H, SD, SL = STATES
WRITES: dict[tuple[int, bytes], dict[State, str]] = {
    (Cmd.RESET_TO_DEFAULT, b""): dict.fromkeys([S, G, R, SS, H, SD], "default") | {SL: "-"},
    (Cmd.SET_MOTOR_PARAM, codec.encode_motor_params(OTHER)): dict.fromkeys(
        [S, G, R, SS, H, SD], "ram"
    )
    | {SL: "-"},
    (Cmd.RESET_POSITION, b""): {S: "reset", G: "-", R: "-", SS: "-", H: "-", SD: "reset", SL: "-"},
    (Cmd.SET_POSITION, b"\x01\x00"): {
        S: "tag>GotoPos",
        G: "tag",
        R: "pending",
        SS: "-",
        H: "-",
        SD: "-",
        SL: "-",
    },
    (Cmd.SET_POSITION_SHORT_1, b"\x01\x00"): {
        S: "tag>GotoPos",
        G: "tag",
        R: "pending",
        SS: "-",
        H: "-",
        SD: "-",
        SL: "-",
    },
    (Cmd.GOTO_SECURE_POSITION, b""): {
        S: "sec>GotoPos",
        G: "sec",
        R: "pending",
        SS: "-",
        H: "-",
        SD: "-",
        SL: "-",
    },
    (Cmd.RUN_INIT, bytes((0x51, 0x10, 0x00, 0x08, 0x00))): {S: ">RunInit"}
    | dict.fromkeys([G, R, SS, H, SD, SL], "-"),
    (Cmd.HARD_STOP, b""): {
        S: "-",
        G: ">HardStop+StepLoss",
        R: ">HardStop+StepLoss",
        SS: ">HardStop+StepLoss",
        H: "-",
        SD: "-",
        SL: "-",
    },
    (Cmd.SOFT_STOP, b""): {G: ">SoftStop"} | dict.fromkeys([S, R, SS, H, SD, SL], "-"),
}


def _observe(n: Node, before: dict[str, object], state: State) -> str:
    if n.state != state:
        extra = "+StepLoss" if n.f["steploss"] and not before["steploss"] else ""
        if n.tagpos != before["tagpos"]:
            return ("sec" if n.tagpos == SEC else "tag") + f">{n.state.value}"
        return f">{n.state.value}{extra}"
    if n.ram != before["ram"]:
        return "ram" if n.ram.irun == OTHER.irun else "default"
    if n.actpos() != before["actpos"] or (n.tagpos == 0 and before["tagpos"] != 0):
        return "reset"
    if n.pending_tag is not None:
        return "pending"
    if n.tagpos != before["tagpos"]:
        return "sec" if n.tagpos == SEC else "tag"
    return "-"


@pytest.mark.parametrize("state", STATES, ids=[s.value for s in STATES])
@pytest.mark.parametrize(("cmd", "params"), list(WRITES), ids=[Cmd(c).name for c, _ in WRITES])
def test_writing_command_in_each_state(state: State, cmd: int, params: bytes) -> None:
    n = node_in(state)
    if state in (State.STOPPED, State.RUNINIT, State.SHUTDOWN) and cmd == Cmd.RESET_POSITION:
        n.ramp.x = 96.0  # a position to reset
    if cmd == Cmd.SET_POSITION_SHORT_1:  # half-stepping only (§6.11.13)
        n.ram = codec.MotorParams(
            PARAMS.irun, PARAMS.ihold, PARAMS.vmax, PARAMS.vmin, PARAMS.secpos, PARAMS.shaft,
            PARAMS.acc, PARAMS.accshape, 0,
        )  # fmt: skip
    if state == State.SHUTDOWN and cmd == Cmd.RESET_TO_DEFAULT:
        n.ram = OTHER
    before = {"tagpos": n.tagpos, "actpos": n.actpos(), "ram": n.ram, "steploss": n.f["steploss"]}
    n.command(cmd, params, T0 + 300_000_000)
    assert _observe(n, before, state) == WRITES[(cmd, params)][state]


# --- reading commands: answered in every state but Sleep (no power) --------------------
@pytest.mark.parametrize("state", STATES, ids=[s.value for s in STATES])
def test_reading_commands_in_each_state(state: State) -> None:
    n = node_in(state)
    powered = state != State.SLEEP
    assert n.publishes(0x20) is powered  # GetActualPos
    assert n.publishes(0x00) is powered  # GetStatus
    n.prepared = (Cmd.GET_OTP_PARAM, 1)
    assert n.publishes(0x3D) is powered


@pytest.mark.parametrize("state", STATES, ids=[s.value for s in STATES])
def test_get_status_leaves_only_shutdown(state: State) -> None:
    n = node_in(state)
    n._clear_flags(T0)
    want = State.STOPPED if state == State.SHUTDOWN else state
    assert n.state == want


# --- Sleep command or LIN timeout ------------------------------------------------------
SLEEP_OUTCOME = {S: "flag", G: "sec", R: "pending", SS: "flag", H: "flag", SD: ">Sleep", SL: "-"}


@pytest.mark.parametrize("state", STATES, ids=[s.value for s in STATES])
def test_sleep_or_lin_timeout_in_each_state(state: State) -> None:
    n = node_in(state)
    tag = n.tagpos
    n.sleep_flag = False  # (a node in Sleep got there with it set)
    n.event(Event.SLEEP, T0 + 300_000_000)
    if n.state != state:
        got = f">{n.state.value}"
    elif n.pending_tag == SEC:
        got = "pending"
    elif n.tagpos != tag:
        got = "sec"
    else:
        got = "flag" if n.sleep_flag else "-"
    assert got == SLEEP_OUTCOME[state]


def test_sleep_in_gotopos_without_secure_position_soft_stops() -> None:
    n = node_in(State.GOTOPOS)
    n.ram = codec.MotorParams(8, 1, 5, 1, 0x400, 0, 0, 0, 3)
    n.event(Event.SLEEP, T0 + 300_000_000)
    assert n.state == State.SOFTSTOP


# --- internal events, weighed at the next tick -----------------------------------------
INTERNAL = {
    "electrical": {S: "ShutDown", G: "HardStop", R: "HardStop", SS: "HardStop"},
    "thermal": {S: "ShutDown", G: "SoftStop", R: "SoftStop"},
}


@pytest.mark.parametrize("kind", list(INTERNAL))
@pytest.mark.parametrize("state", [S, G, R, SS], ids=["Stopped", "GotoPos", "RunInit", "SoftStop"])
def test_internal_events_at_the_next_tick(kind: str, state: State) -> None:
    n = node_in(state)
    now = T0 + 300_000_000
    if kind == "electrical":
        n.set_condition("cpfail", True, now)
    else:
        n.set_condition("temp", 160.0, now)
    n.advance(n.next_tick)  # exactly one tick
    want = INTERNAL[kind].get(state, state.value)
    assert n.state.value == want
    if state in (G, R, SS) and want != state.value:
        assert n.f["steploss"] == 1  # §5.2.2: a stop on such an event may lose steps


def test_hardstop_and_softstop_end_in_stopped_with_tagpos_actpos() -> None:
    for state in (State.SOFTSTOP, State.HARDSTOP):
        n = node_in(state)
        n.advance(T0 + 10_000_000_000)
        assert n.state == State.STOPPED
        assert n.tagpos == n.actpos() != 0


def test_electrical_defect_walks_gotopos_to_hardstop_stopped_shutdown() -> None:
    n = node_in(State.GOTOPOS)
    now = T0 + 300_000_000
    n.set_condition("ovc1", True, now)
    seen = []
    for _ in range(3):
        n.advance(n.next_tick)
        seen.append(n.state.value)
    assert seen == ["HardStop", "Stopped", "ShutDown"]
    assert n.next_tick - now <= 4 * TICK_NS


def test_the_data_table_matches_the_transcription() -> None:
    """tables.PRIORITY_ENCODER says the same as the hand transcription above."""
    rows = {
        Event.RESET_POSITION: (Cmd.RESET_POSITION, b""),
        Event.RUN_INIT: (Cmd.RUN_INIT, bytes((0x51, 0x10, 0x00, 0x08, 0x00))),
        Event.SOFT_STOP: (Cmd.SOFT_STOP, b""),
        Event.HARD_STOP: (Cmd.HARD_STOP, b""),
    }
    for event, key in rows.items():
        for state, outcome in WRITES[key].items():
            assert (PRIORITY_ENCODER[event][state] == Action.IGNORED) == (outcome == "-")
