"""CiA 402 drive in process: the PDS table, trajectories against closed forms, physics
determinism, torque/inertia, quick stop, faults. Ref: CiA 402-2; TMC8670 §6-§9."""

from __future__ import annotations

import itertools

import pytest

from ecatsim.device import cia402
from ecatsim.device.cia402 import Command, PdsState
from ecatsim.device.description import default_description
from ecatsim.device.drive import CSP, CST, PP, PV, Drive
from ecatsim.device.servo import MotorParams, Profile
from ecatsim.slave.al import AlState
from ecatsim.slave.od_build import build_od

MS = 1_000_000

#: (state, command) -> next state, for every pair (None: the command does nothing).
EXPECTED = {
    (PdsState.SWITCH_ON_DISABLED, Command.SHUTDOWN): PdsState.READY_TO_SWITCH_ON,
    (PdsState.READY_TO_SWITCH_ON, Command.SWITCH_ON): PdsState.SWITCHED_ON,
    (PdsState.READY_TO_SWITCH_ON, Command.SWITCH_ON_ENABLE): PdsState.SWITCHED_ON,
    (PdsState.SWITCHED_ON, Command.SWITCH_ON_ENABLE): PdsState.OPERATION_ENABLED,
    (PdsState.OPERATION_ENABLED, Command.SWITCH_ON): PdsState.SWITCHED_ON,
    (PdsState.SWITCHED_ON, Command.SHUTDOWN): PdsState.READY_TO_SWITCH_ON,
    (PdsState.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE): PdsState.SWITCH_ON_DISABLED,
    (PdsState.READY_TO_SWITCH_ON, Command.QUICK_STOP): PdsState.SWITCH_ON_DISABLED,
    (PdsState.OPERATION_ENABLED, Command.SHUTDOWN): PdsState.READY_TO_SWITCH_ON,
    (PdsState.OPERATION_ENABLED, Command.DISABLE_VOLTAGE): PdsState.SWITCH_ON_DISABLED,
    (PdsState.SWITCHED_ON, Command.DISABLE_VOLTAGE): PdsState.SWITCH_ON_DISABLED,
    (PdsState.SWITCHED_ON, Command.QUICK_STOP): PdsState.SWITCH_ON_DISABLED,
    (PdsState.OPERATION_ENABLED, Command.QUICK_STOP): PdsState.QUICK_STOP_ACTIVE,
    (PdsState.QUICK_STOP_ACTIVE, Command.DISABLE_VOLTAGE): PdsState.SWITCH_ON_DISABLED,
    (PdsState.FAULT, Command.FAULT_RESET): PdsState.SWITCH_ON_DISABLED,
    (PdsState.QUICK_STOP_ACTIVE, Command.SWITCH_ON_ENABLE): PdsState.OPERATION_ENABLED,
}


@pytest.mark.parametrize(("state", "cmd"), list(itertools.product(PdsState, Command)))
def test_every_state_command_pair(state: PdsState, cmd: Command) -> None:
    r = cia402.step(state, cmd)
    assert (None if r is None else r[1]) == EXPECTED.get((state, cmd))


@pytest.mark.parametrize(
    ("cw", "prev", "cmd"),
    [
        (0x06, 0, Command.SHUTDOWN),
        (0x07, 0, Command.SWITCH_ON),
        (0x0F, 0, Command.SWITCH_ON_ENABLE),
        (0x00, 0, Command.DISABLE_VOLTAGE),
        (0x02, 0, Command.QUICK_STOP),
        (0x80, 0, Command.FAULT_RESET),
        (0x80, 0x80, Command.NONE),
        (0x0B, 0, Command.QUICK_STOP),
    ],
)
def test_controlword_decoding(cw: int, prev: int, cmd: Command) -> None:
    assert cia402.decode(cw, prev) == cmd


def test_profile_matches_closed_form() -> None:
    p = Profile()
    p.target, p.vmax, p.acc, p.dec = 50_000.0, 5_000.0, 40_000.0, 20_000.0
    t, dt, peak = 0.0, 1e-4, 0.0
    while (p.pos != p.target or p.vel != 0.0) and t < 60:
        p.step(dt)
        t += dt
        peak = max(peak, p.vel)
    closed = 50_000 / 5_000 + 5_000 / (2 * 40_000) + 5_000 / (2 * 20_000)
    assert abs(t - closed) < 0.002
    assert peak == 5_000.0
    # triangular: the peak is sqrt(2 a d D / (a + d))
    q = Profile()
    q.target, q.vmax, q.acc, q.dec = 1_000.0, 1e9, 40_000.0, 40_000.0
    top = 0.0
    for _ in range(100_000):
        q.step(dt)
        top = max(top, q.vel)
        if q.pos == q.target and q.vel == 0:
            break
    assert abs(top - (40_000 * 1_000) ** 0.5) / (40_000 * 1_000) ** 0.5 < 0.01


def make(params: MotorParams | None = None) -> tuple[Drive, list[tuple[int, int, bytes]]]:
    od = build_od(default_description())
    emcys: list[tuple[int, int, bytes]] = []
    d = Drive(od, params, lambda c, r, b: emcys.append((c, r, b)))
    d.al_state_changed(AlState.OP, 0)
    return d, emcys


def statusword(d: Drive) -> int:
    """6041h, an integer object."""
    sw = d.od.value(0x6041)
    assert isinstance(sw, int)
    return sw


def state_of(d: Drive) -> PdsState:
    """The drive's PDS state, read anew (a call, not an attribute a type checker narrows)."""
    return d.state


def command(d: Drive, t: int, cw: int, **objs: int) -> None:
    for k, v in objs.items():
        d.od.set(int(k[1:], 16), 0, v)
    d.od.set(0x6040, 0, cw)
    d.outputs_applied(t)
    d.update_inputs(t)


def enable(d: Drive, mode: int, t: int = 0) -> int:
    command(d, t, 0x06, x6060=mode)
    assert statusword(d) & 0x6F == 0x21
    command(d, t + MS, 0x07)
    assert statusword(d) & 0x6F == 0x23
    command(d, t + 2 * MS, 0x0F)
    assert statusword(d) & 0x6F == 0x27
    return t + 2 * MS


def test_statusword_sequence_with_remote_and_voltage_bits() -> None:
    d, _ = make()
    d.update_inputs(0)
    assert d.od.value(0x6041) == 0x0240  # switch on disabled + remote
    command(d, MS, 0x06)
    assert d.od.value(0x6041) == 0x0231
    command(d, 2 * MS, 0x07)
    assert d.od.value(0x6041) == 0x0233
    command(d, 3 * MS, 0x0F, x6060=PV)
    assert statusword(d) & 0x02FF == 0x0237


def test_cst_acceleration_is_torque_over_inertia() -> None:
    params = MotorParams(coulomb=0.0, viscous=0.0)
    d, _ = make(params)
    t = enable(d, CST)
    command(d, t + MS, 0x0F, x6071=1000)  # 1000 mA
    v0 = d.servo.omega
    command(d, t + 101 * MS, 0x0F)
    accel = (d.servo.omega - v0) / 0.1
    expected = params.kt * 1.0 / params.inertia
    assert abs(accel - expected) / expected < 0.05


def test_physics_is_deterministic() -> None:
    def run() -> list[tuple[int, int, int]]:
        d, _ = make()
        t = enable(d, PV)
        trace = []
        for i in range(300):
            t += 997_000  # an irregular frame rate: substeps are fixed anyway
            command(d, t, 0x0F, x60FF=1500 if i < 150 else -300)
            trace.append((d.od.value(0x6064), d.od.value(0x606C), d.od.value(0x6077)))
        return trace  # type: ignore[return-value]

    assert run() == run()


def test_pv_reaches_velocity_on_the_ramp() -> None:
    d, _ = make()
    t = enable(d, PV)
    d.od.set(0x6083, 0, 2000)
    reached_at = None
    for i in range(1, 2000):
        command(d, t + i * MS, 0x0F, x60FF=2000)
        if reached_at is None and statusword(d) & 0x0400:
            reached_at = i
            break
    assert reached_at is not None and 950 <= reached_at <= 1150  # 2000 rpm at 2000 rpm/s


def test_pp_move_and_quick_stop() -> None:
    d, _ = make()
    t = enable(d, PP)
    command(d, t + MS, 0x0F, x607A=50_000, x6081=500, x6083=2000, x6084=2000)
    command(d, t + 2 * MS, 0x1F)  # new set point
    assert statusword(d) & 0x1000  # set-point acknowledge
    peak = 0
    for i in range(3, 3000):
        command(d, t + i * MS, 0x1F)
        peak = max(peak, abs(int(d.od.value(0x606C))))
        if statusword(d) & 0x0400:
            break
    assert abs(int(d.od.value(0x6064)) - 50_000) <= 20
    assert abs(peak - 500) <= 10
    # quick stop from 1000 rpm in pv decelerates at 6085
    command(d, t + 4000 * MS, 0x0F, x6060=PV, x60FF=1000, x6083=10_000)
    for i in range(1, 400):
        command(d, t + (4000 + i) * MS, 0x0F)
    assert abs(d.servo.rpm - 1000) < 20
    command(d, t + 4400 * MS, 0x0B, x6085=5000)
    assert d.state == PdsState.QUICK_STOP_ACTIVE
    for i in range(1, 400):
        command(d, t + (4400 + i) * MS, 0x0B)
        if state_of(d) == PdsState.SWITCH_ON_DISABLED:
            break
    assert 180 <= i <= 230  # 1000 rpm / 5000 rpm/s = 200 ms


def test_injected_overcurrent_faults_and_recovers() -> None:
    d, emcys = make()
    t = enable(d, CSP)
    d.inject("overcurrent")
    command(d, t + 10 * MS, 0x0F)
    assert d.state == PdsState.FAULT
    assert statusword(d) & 0x4F == 0x08
    assert d.od.value(0x603F) == 0x2310
    assert emcys == [(0x2310, 0x02, b"")]
    command(d, t + 11 * MS, 0x8F)
    assert d.state == PdsState.FAULT  # cause still present
    d.inject("overcurrent", False)
    command(d, t + 12 * MS, 0x0F)
    command(d, t + 13 * MS, 0x8F)  # rising edge of bit 7
    assert state_of(d) == PdsState.SWITCH_ON_DISABLED


def test_leaving_op_stops_the_motor() -> None:
    d, _ = make()
    t = enable(d, PV)
    for i in range(1, 300):
        command(d, t + i * MS, 0x0F, x60FF=1000)
    assert d.servo.rpm > 100
    d.al_state_changed(AlState.SAFEOP, t + 300 * MS)
    assert state_of(d) == PdsState.SWITCH_ON_DISABLED
    d.update_inputs(t + 2000 * MS)
    assert abs(d.servo.rpm) < 1.0


def test_current_loop_step_response_from_2041_gains() -> None:
    """Default 2041h gains (pole-zero cancellation, decision D15): a torque current step
    on a locked rotor rises like a first-order lag of 250 us and settles exactly."""
    from ecatsim.device.servo import Servo

    p = MotorParams(inertia=1e9)  # a locked rotor
    s = Servo(p)
    trace = []
    for _ in range(30):
        s.step(1000.0)
        trace.append(s.iq_ma)
    # the digital loop at 10 kHz brackets the continuous lag: 55 % at 200 us, 70 % at 300 us
    assert 500 <= trace[1] <= 700 and 650 <= trace[2] <= 800, trace[:5]
    assert abs(trace[-1] - 1000.0) < 1.0  # settled, no steady-state error


def test_current_loop_is_limited_by_the_supply_voltage() -> None:
    from ecatsim.device.servo import Servo

    p = MotorParams(inertia=1e9, supply_voltage=0.5)  # 0.5 V over 1 ohm: 500 mA at most
    s = Servo(p)
    for _ in range(200):
        s.step(2000.0)
    assert abs(s.iq_ma - 500.0) < 1.0


def test_2041_gains_written_and_used() -> None:
    desc = default_description()
    od = build_od(desc)
    d = Drive(od)
    assert od.value(0x2041, 5) == 1024 and od.value(0x2041, 6) == 4000  # L, R over 250 us
    od.set(0x2041, 5, 256)  # 1 V/A: a slower loop
    d._load_gains()
    assert d.servo.gains.cur_kp == 1.0


def test_published_values_are_ints_in_range_whichever_path_writes_them() -> None:
    """_publish writes C integers only where they changed (P34): an entry holding a bool,
    a string or an int of the same value ends as that int; values beyond a C integer (an
    absurd encoder angle) go the Python path, clamped to the entry's range alike."""
    od = build_od(default_description())
    d = Drive(od)
    d.update_inputs(0)
    assert [type(od.value(i, 0)) for i in (0x6041, 0x6064, 0x606C)] == [int, int, int]
    sw = od.value(0x6041, 0)
    od.set(0x6041, 0, bool(sw) if sw in (0, 1) else "stale")
    od.set(0x6064, 0, True)
    od.set(0x6077, 0, 1 << 80)
    d.update_inputs(0)
    assert (od.value(0x6041, 0), type(od.value(0x6041, 0))) == (sw, int)
    assert (od.value(0x6064, 0), type(od.value(0x6064, 0))) == (0, int)
    assert (od.value(0x6077, 0), type(od.value(0x6077, 0))) == (0, int)
    for angle, pos in ((1e30, (1 << 31) - 1), (-1e30, -(1 << 31)), (3e5, None)):
        d.servo.angle = angle
        d.update_inputs(0)
        want = d.servo.read_counts()
        clamped = max(-(1 << 31), min((1 << 31) - 1, want))
        assert od.value(0x6064, 0) == clamped == (pos if pos is not None else want)
        assert od.value(0x60F4, 0) == max(-(1 << 31), min((1 << 31) - 1, round(d.p_demand - want)))


def test_decode_and_the_transitions_give_the_enum_members_themselves() -> None:
    """The drive tests commands and states by identity (P23, P36): decode() returns
    Command members and the transition table PdsState members, never equal ints."""
    members = {id(c) for c in Command}
    for cw in range(0x100):
        for prev in (0, 0x80):
            assert id(cia402.decode(cw, prev)) in members
    for number, nxt in cia402.TRANSITIONS.values():
        assert any(nxt is st for st in PdsState), number


def test_a_drive_of_the_segment_names_its_slave_in_its_log_lines() -> None:
    """128 drives enabled together log 128 pds_state lines: each says which slave."""
    from structlog.testing import capture_logs

    from tests.support.tinymaster import drive_of, segment_of

    with capture_logs() as logs:
        seg, _ = segment_of(2, device="tmc8670")
        drive = drive_of(seg, 1)
        drive._enter(PdsState.READY_TO_SWITCH_ON, "t2")
    assert logs[-1] == {
        "event": "pds_state",
        "slave": 1,
        "state": "READY_TO_SWITCH_ON",
        "why": "t2",
        "log_level": "info",
    }
