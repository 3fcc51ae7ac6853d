"""A LIN master on the pty of ``ecatsim lin``: the TMC211 acceptance exchanges.

Signal-based frames are encoded and decoded with ldfparser from the shipped LDF
(config/tmc211.ldf); the reserved-identifier frames (0x3C/0x3D) are written from the
TMC211 datasheet's byte tables (§6.11). The door runs in-process on a ManualClock, so
motion takes simulated time; one test runs the ``ecatsim lin`` command itself.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
import tty
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import ldfparser
import pytest

from ecatsim.lin import codec
from ecatsim.lin.config import NodeConfig
from ecatsim.lin.frame import SLAVE_RESPONSE, header
from ecatsim.lin.frame import frame as lin_frame
from ecatsim.lin.server import LinDoor
from ecatsim.lin.tables import VMAX_SIXTEENTH, Cmd, RomPointer, State
from tests.support.linmaster import LinMaster, make_door, node_state

ROOT = Path(__file__).resolve().parents[2]
LDF = ldfparser.parse_ldf(str(ROOT / "config" / "tmc211.ldf"))

LEFT, RIGHT = 0x01, 0x02  # the LDF's two nodes
NODES = (
    NodeConfig(name="left", otp=bytes((0, 0, LEFT, 0, 0, 0, 0, 0))),
    NodeConfig(name="right", otp=bytes((0, 0, RIGHT, 0, 0, 0, 0, 0))),
)
#: Irun 8, Ihold 2, Vmax 5 (228 FS/s), Vmin 1 (7 FS/s), Acc 3 (3609 FS/s²), 1/16 steps,
#: secure position 0x010 (= 512)
PARAMS = codec.MotorParams(irun=8, ihold=2, vmax=5, vmin=1, secpos=0x010, acc=3, stepmode=3)


def frame_id(name: str) -> int:
    fid: int = LDF.get_frame(name).frame_id
    return fid


def send(m: LinMaster, name: str, **signals: Any) -> None:
    """A master-published LDF frame, encoded by ldfparser."""
    data = bytes(LDF.get_frame(name).encode(signals))
    assert m.send(frame_id(name), data) == b""


def read(m: LinMaster, name: str) -> dict[str, Any] | None:
    """A node-published LDF frame, decoded by ldfparser (raw values)."""
    data = m.read(frame_id(name))
    if data is None:
        return None
    out: dict[str, Any] = LDF.get_frame(name).decode_raw(data)
    return out


def actpos(m: LinMaster, node: str) -> int:
    r = read(m, f"GetActualPos_{node}")
    assert r is not None
    p = f"GAP_{node}"
    return codec.s16(r[f"{p}_ActPosHi"], r[f"{p}_ActPosLo"])


def set_position(m: LinMaster, node: str, pos: int) -> None:
    hi, lo = codec.u16(pos)
    send(m, f"SetPosition_{node}", **{f"SP_{node}_TagPosHi": hi, f"SP_{node}_TagPosLo": lo})


def assign_ldf_ids(m: LinMaster) -> None:
    """The identifiers the LDF uses: per node by address, the shared ones by broadcast."""
    for name, ad in (("left", LEFT), ("right", RIGHT)):
        m.assign(
            ad,
            [
                (RomPointer.GET_STATUS, frame_id(f"GetStatus_{name}")),
                (RomPointer.GET_ACTUAL_POS, frame_id(f"GetActualPos_{name}")),
                (RomPointer.SET_POSITION, frame_id(f"SetPosition_{name}")),
            ],
        )
    shared = [
        (RomPointer.GENERAL_PURPOSE_2, frame_id("GeneralPurpose2")),
        (RomPointer.GENERAL_PURPOSE_4, frame_id("GeneralPurpose4")),
        (RomPointer.PREPARING, frame_id("Preparing")),
        (RomPointer.SET_POSITION_SHORT_1, frame_id("SetPositionShort1")),
    ]
    m.assign(0, shared, broad=True)


def gp2(m: LinMaster, command: str, ad: int, broad: bool = False) -> None:
    send(m, "GeneralPurpose2", GP2_Command=command, GP2_AD=ad, GP2_Broad=0 if broad else 1)


@pytest.fixture
def bus(tmp_path: Path) -> Iterator[tuple[LinDoor, LinMaster]]:
    door, _clock, m = make_door(tmp_path, NODES)
    assign_ldf_ids(m)
    yield door, m
    door.close()


def start(m: LinMaster, ad: int, params: codec.MotorParams = PARAMS) -> None:
    m.full_status(ad)
    m.motor_param(ad, params)


def test_activation_by_the_first_get_full_status(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    node = door.bus.nodes[0]
    assert node_state(node) == State.SHUTDOWN  # §5.1.10: power-on enters ShutDown
    st = read(m, "GetStatus_left")
    assert st is not None and st["GS_left_AD"] == LEFT
    m.motor_param(LEFT, PARAMS)
    # GetStatus read <VddReset>; it is the first GetFullStatus that we test: power-cycle
    door.ctl("power", ["left"])
    assign_ldf_ids(m)
    m.motor_param(LEFT, PARAMS)
    set_position(m, "left", 1000)  # ignored: <VddReset> = 1 (§5.2.3 note)
    m.wait(0.5)
    assert actpos(m, "left") == 0
    first, _second = m.full_status(LEFT)
    assert first is not None and first[4] == 0x80  # <VddReset> read once
    assert node_state(node) == State.STOPPED
    first, _ = m.full_status(LEFT)
    assert first is not None and first[4] == 0x00
    set_position(m, "left", 1000)
    m.wait(1.0)
    assert actpos(m, "left") == 1000


def test_set_motor_param_read_back_with_get_full_status(bus: tuple[LinDoor, LinMaster]) -> None:
    _door, m = bus
    m.full_status(LEFT)
    p = codec.MotorParams(irun=0xC, ihold=0x4, vmax=9, vmin=3, secpos=0x2A5, shaft=1, acc=7,
                          accshape=1, stepmode=2)  # fmt: skip
    m.motor_param(LEFT, p)
    first, second = m.full_status(LEFT)
    assert first == bytes((0x80 | LEFT, 0xC4, 0x93, 0x80 | 2 << 5 | 0x10 | 7, 0, 0x02, 0, 0xFF))
    assert second == bytes((0x80 | LEFT, 0, 0, 0, 0, 0xA5, 0xF8 | 2, 0xFF))


def test_set_position_reached_with_the_sheets_velocity(bus: tuple[LinDoor, LinMaster]) -> None:
    _door, m = bus
    start(m, LEFT)
    t0 = m.clock.t
    set_position(m, "left", 16000)  # 1000 full steps
    # Vmax 5 = 228 FS/s = 3647 1/16 micro-steps/s (Table 3), Vmin 1 = 7 FS/s (Table 4),
    # Acc 3 = 3609 FS/s² (Table 5): ramps of (228² - 7²) / (2 * 3609) = 7.2 full steps
    m.wait(1.0)
    p1, t1 = actpos(m, "left"), m.clock.t
    m.wait(1.0)
    p2, t2 = actpos(m, "left"), m.clock.t
    speed = (p2 - p1) / ((t2 - t1) / 1e9)
    assert abs(speed - VMAX_SIXTEENTH[5]) < 0.005 * VMAX_SIXTEENTH[5]
    vmax, vmin, acc = 3647 / 16, 7, 3609
    ramp_fs = (vmax**2 - vmin**2) / (2 * acc)
    expect_s = 2 * (vmax - vmin) / acc + (1000 - 2 * ramp_fs) / vmax
    while actpos(m, "left") != 16000:
        m.wait(0.01)
    took = (m.clock.t - t0) / 1e9
    assert expect_s <= took <= expect_s + 0.1  # polled every ~30 ms


def test_soft_stop_and_hard_stop(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    left, right = door.bus.nodes
    for ad in (LEFT, RIGHT):
        start(m, ad, codec.MotorParams(8, 2, 5, 1, 0x010, 0, 1, 0, 3))  # Acc 1: 218 FS/s²
    set_position(m, "left", 30000)
    set_position(m, "right", 30000)
    m.wait(1.0)
    gp2(m, "SoftStop", LEFT)
    gp2(m, "HardStop", RIGHT)
    assert left.state == State.SOFTSTOP
    soft_at, hard_at = actpos(m, "left"), actpos(m, "right")
    m.wait(1.5)
    assert left.state == right.state == State.STOPPED
    soft_end, hard_end = actpos(m, "left"), actpos(m, "right")
    # HardStop: immediate; SoftStop: decelerates from 228 to 7 FS/s at 218 FS/s²
    assert hard_end - hard_at < 3647 * 0.05
    ramp = (228**2 - 7**2) / (2 * 218) * 16
    assert 0.8 * ramp < soft_end - soft_at < 1.2 * ramp
    ls = read(m, "GetStatus_left")
    rs = read(m, "GetStatus_right")
    assert ls is not None and rs is not None
    assert (ls["GS_left_StepLoss"], rs["GS_right_StepLoss"]) == (0, 1)
    assert left.tagpos == soft_end and right.tagpos == hard_end  # TagPos = ActPos


def test_run_init_finds_the_stall(tmp_path: Path) -> None:
    stall = NodeConfig(name="left", otp=bytes((0, 0, LEFT, 0, 0, 0, 0, 0)), stops=(-3000, 1e9))
    door, _clock, m = make_door(tmp_path, (stall, NODES[1]))
    assign_ldf_ids(m)
    node = door.bus.nodes[0]
    start(m, LEFT)
    set_position(m, "left", 2000)  # somewhere away from the stop
    m.wait(1.0)
    # RunInit (§6.11.9): Vmax 5 Vmin 1, first motion to -20000 (into the stop), second to
    # -19800: 200 micro-steps back out of it at Vmin; then ActPos = 0 and SecPos
    m.app(Cmd.RUN_INIT, LEFT, bytes((0x51, *codec.u16(-20000), *codec.u16(-19800))))
    assert node_state(node) == State.RUNINIT
    m.wait(5.0)
    assert node_state(node) == State.RUNINIT  # first motion counts on, the rotor sits at the stop
    assert node.motor.rotor == -3000
    while node_state(node) == State.RUNINIT:
        m.wait(0.002)
    assert node.motor.rotor == -2800
    # the reference is 200 micro-steps from the stop; then the secure position 512 follows
    while node_state(node) != State.STOPPED or actpos(m, "left") != 512:
        m.wait(0.2)
    assert node.motor.rotor == -2800 + 512
    set_position(m, "left", -200)
    m.wait(1.0)
    assert node.motor.rotor == -3000


def test_run_init_deadlock_needs_hardstop_and_get_full_status(
    bus: tuple[LinDoor, LinMaster],
) -> None:
    door, m = bus
    node = door.bus.nodes[0]
    start(m, LEFT)
    # §5.1.11: a first target equal to the actual position deadlocks the circuit
    m.app(Cmd.RUN_INIT, LEFT, bytes((0x51, 0, 0, *codec.u16(100))))
    m.wait(2.0)
    assert node_state(node) == State.RUNINIT
    set_position(m, "left", 500)  # no effect now
    gp2(m, "SoftStop", LEFT)  # RunInit is not interrupted by SoftStop
    m.wait(1.0)
    assert node_state(node) == State.RUNINIT and actpos(m, "left") == 0
    gp2(m, "HardStop", LEFT)
    m.wait(0.1)
    assert node_state(node) == State.STOPPED
    set_position(m, "left", 500)  # ignored: <StepLoss> until GetFullStatus
    m.wait(0.5)
    assert actpos(m, "left") == 0
    m.full_status(LEFT)
    set_position(m, "left", 500)
    m.wait(0.5)
    assert actpos(m, "left") == 500


def test_goto_secure_position_by_broadcast(bus: tuple[LinDoor, LinMaster]) -> None:
    _door, m = bus
    start(m, LEFT)
    start(m, RIGHT, codec.MotorParams(8, 2, 5, 1, 0x7F0, 0, 3, 0, 3))  # SecPos -16 -> -512
    gp2(m, "GotoSecurePosition", 0, broad=True)
    m.wait(1.0)
    assert (actpos(m, "left"), actpos(m, "right")) == (512, -512)


def test_secure_position_after_lin_loss(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    left, right = door.bus.nodes
    start(m, LEFT)
    start(m, RIGHT, codec.MotorParams(8, 2, 5, 1, 0x400, 0, 3, 0, 3))  # secure position off
    set_position(m, "left", 6000)
    set_position(m, "right", 6000)
    m.wait(0.5)
    m.wait(1.3, keepalive=False)  # the master goes quiet: 25000 bit times
    assert left.sleep_flag and left.tagpos == 512  # §5.1.8: on to the secure position
    assert right.state in (State.SOFTSTOP, State.STOPPED, State.SLEEP)
    m.wait(3.0, keepalive=False)
    assert left.state == right.state == State.SLEEP
    assert left.motor.rotor == 512
    assert right.motor.rotor < 6000  # no secure position: it stopped, then slept


def test_sleep_and_wake(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    start(m, LEFT)
    set_position(m, "left", 2000)
    m.wait(1.0)
    m.send(0x3C, bytes((0x00, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF)))  # §6.11.15
    m.wait(1.0, keepalive=False)  # (any frame would cancel the <Sleep> flag, note 4)
    assert all(n.state == State.SLEEP for n in door.bus.nodes)
    assert door.bus.nodes[0].motor.rotor == 512  # to the secure position first (§5.1.12)
    m.prepare(Cmd.GET_FULL_STATUS, LEFT)  # wakes the nodes; not answered: they wake up
    assert m.read(SLAVE_RESPONSE) is None
    assert door.bus.nodes[0].state == State.SHUTDOWN  # waking is a power-on reset
    assert read(m, "GetStatus_left") is None  # identifiers were RAM
    first, _ = m.full_status(LEFT)
    assert first is not None and first[4] & 0x80  # <VddReset>


def test_several_nodes_broadcast_and_dynamic_ids(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    for ad in (LEFT, RIGHT):
        start(m, ad)
    # broadcast SetPosition in a general-purpose 4-byte frame: both nodes
    send(m, "GeneralPurpose4", GP4_Command="SetPosition", GP4_AD=0, GP4_Broad=0,
         GP4_ParamHi=0x07, GP4_ParamLo=0xD0)  # fmt: skip
    m.wait(1.0)
    assert (actpos(m, "left"), actpos(m, "right")) == (2000, 2000)
    # addressed (Broad = 1) to the right node only
    send(m, "GeneralPurpose4", GP4_Command="SetPosition", GP4_AD=RIGHT, GP4_Broad=1,
         GP4_ParamHi=0x03, GP4_ParamLo=0xE8)  # fmt: skip
    m.wait(1.0)
    assert (actpos(m, "left"), actpos(m, "right")) == (2000, 1000)
    # GetFullStatus prepared by the LDF's type #7 frame, read on 0x3D
    send(m, "Preparing", PREP_Command="GetFullStatus", PREP_AD=RIGHT, PREP_One=1)
    first = m.read(SLAVE_RESPONSE)
    assert first is not None and first[0] == 0x80 | RIGHT and first[2] == 0x51
    # a new identifier for the left node's GetStatus, through 0x3C (§6.8)
    m.assign(LEFT, [(RomPointer.GET_STATUS, 0x05)])
    assert read(m, "GetStatus_left") is None  # 0x01 no longer answers
    data = m.read(0x05)
    assert data is not None and data[0] == LEFT
    # two nodes given the same identifier answer together: wired-AND bit by bit, LSB
    # first; left (0x01) sends a recessive bit 0 where right (0x02) is dominant: bit error
    m.assign(RIGHT, [(RomPointer.GET_STATUS, 0x05)])
    data = m.read(0x05)
    assert data is not None and data[0] == RIGHT
    assert door.bus.collisions == 1
    assert [n.lin_errors & 1 for n in door.bus.nodes] == [1, 0]


def test_otp_zapping_persists_across_a_restart(tmp_path: Path) -> None:
    otp_file = tmp_path / "left.otp"
    cfg = (NodeConfig(name="left", otp=bytes((0, 0, LEFT, 0, 0, 0, 0, 0)), otp_file=otp_file),)
    door, _clock, m = make_door(tmp_path, cfg)
    m.full_status(LEFT)
    m.app(Cmd.SET_OTP_PARAM, LEFT, bytes((0xFA, 0x04)))  # PA[3:0] |= 0b0100 -> AD 0x05
    m.app(Cmd.SET_OTP_PARAM, LEFT, bytes((0xFB, 0x85)))  # Irun 8, Ihold 5
    m.app(Cmd.SET_OTP_PARAM, LEFT, bytes((0xFA, 0x00)))  # zeros change nothing
    assert otp_file.read_bytes() == bytes((0, 0, 0x05, 0x85, 0, 0, 0, 0))
    door.close()
    door, _clock, m = make_door(tmp_path, cfg)  # a restart: the file is the chip's OTP
    m.prepare(Cmd.GET_OTP_PARAM, 0x05)
    assert m.read(SLAVE_RESPONSE) == bytes((0, 0, 0x05, 0x85, 0, 0, 0, 0))
    first, _ = m.full_status(0x05)
    assert first is not None and first[1] == 0x85  # RAM loaded from the zapped OTP
    # LOCKBG (§5.2.3 Table 10) ends zapping of 0x02-0x07
    m.app(Cmd.SET_OTP_PARAM, 0x05, bytes((0xFF, 0x01)))
    m.app(Cmd.SET_OTP_PARAM, 0x05, bytes((0xFB, 0xFF)))
    assert otp_file.read_bytes() == bytes((0, 0, 0x05, 0x85, 0, 0, 0, 0x01))
    door.close()


FAULTS = [
    # ctl command and arguments, fault on, fault off, the flags it sets in GetFullStatus
    # frame 1 as (byte index, mask)
    ("temp", "150", "25", [(4, 0x04), (4, 0x02)]),  # <TW>, Tinfo = 10
    ("temp", "160", "25", [(4, 0x08), (4, 0x04), (4, 0x03)]),  # <TSD>, <TW>, Tinfo = 11
    ("vbat", "8.0", "12", [(4, 0x10)]),  # <UV2>
    ("ovc1", "on", "off", [(5, 0x08), (4, 0x20)]),  # <OVC1>, <ElDef>
    ("ovc2", "on", "off", [(5, 0x04), (4, 0x20)]),  # <OVC2>, <ElDef>
    ("cpfail", "on", "off", [(5, 0x01)]),  # <CPFail>
    ("esw", "closed", "auto", [(5, 0x10)]),  # <ESW> (a state, not latched)
]


@pytest.mark.parametrize(("kind", "on", "off", "bits"), FAULTS, ids=[f[0] + f[1] for f in FAULTS])
def test_every_flag_set_by_a_fault_and_reset_by_get_full_status(
    bus: tuple[LinDoor, LinMaster], kind: str, on: str, off: str, bits: list[tuple[int, int]]
) -> None:
    door, m = bus
    start(m, LEFT)
    first, _ = m.full_status(LEFT)
    assert first is not None and first[4] == 0 and first[5] & 0xFD == 0
    door.ctl(kind, ["left", on])
    m.wait(0.01)
    first, _ = m.full_status(LEFT)
    assert first is not None
    for i, mask in bits:
        assert first[i] & mask == mask, (i, mask, first.hex())
    door.ctl(kind, ["left", off])
    m.wait(0.01)
    first, _ = m.full_status(LEFT)  # still latched when read, reset by this read
    assert first is not None
    latched = kind != "esw" and kind != "temp"
    if latched:
        for i, mask in bits:
            assert first[i] & mask == mask
    first, _ = m.full_status(LEFT)
    assert first is not None and first[4] == 0 and first[5] & 0xFD == 0


def test_shutdown_on_a_fault_and_back_after_get_full_status(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    node = door.bus.nodes[0]
    start(m, LEFT)
    set_position(m, "left", 20000)
    m.wait(0.5)
    door.ctl("cpfail", ["left", "on"])
    m.wait(0.1)
    assert node_state(node) == State.SHUTDOWN  # HardStop, Stopped, ShutDown (Table 8)
    assert door.ctl("nodes", [])["nodes"][0]["current_ma"] == 0  # bridges in Hi-Z
    m.full_status(LEFT)
    assert node_state(node) == State.SHUTDOWN  # the condition is still there
    door.ctl("cpfail", ["left", "off"])
    m.full_status(LEFT)
    assert node_state(node) == State.STOPPED


def test_irun_to_ihold_after_a_motion(bus: tuple[LinDoor, LinMaster]) -> None:
    door, m = bus
    start(m, LEFT)
    set_position(m, "left", 160)
    while door.bus.nodes[0].state != State.STOPPED:
        m.wait(0.002)
    assert door.ctl("nodes", [])["nodes"][0]["current_ma"] == 238  # Irun 8 (Table 12)
    m.wait(0.15)  # one full step at Vmin = 7 FS/s is 143 ms (§5.3.2)
    assert door.ctl("nodes", [])["nodes"][0]["current_ma"] == 84  # Ihold 2


def test_bad_frames_are_ignored_and_recorded(bus: tuple[LinDoor, LinMaster]) -> None:
    _door, m = bus
    start(m, LEFT)
    m.full_status(LEFT)
    assert m.raw(bytes((0x00, 0x55, 0x01 ^ 0x40))) == b""  # parity: header error
    m.wait(0.02)
    bad = bytearray(header(0x11) + bytes((0x10, 0x00, 0x00)))  # wrong checksum
    assert m.raw(bytes(bad)) == b""
    m.wait(0.02)
    m.raw(header(0x11) + b"\x10")  # short: timeout error
    m.wait(0.02)
    m.raw(b"\x12\x34")  # noise
    m.wait(0.02)
    assert actpos(m, "left") == 0
    first, _ = m.full_status(LEFT)
    assert first is not None and first[6] == 0x0E  # Table 14: timeout, data, header
    first, _ = m.full_status(LEFT)
    assert first is not None and first[6] == 0x00  # reset by GetFullStatus


def test_ecatsim_lin_command_on_a_real_clock(tmp_path: Path) -> None:
    """The command: a pty a master opens, answers in time, ctl status, clean exit."""
    link, sock = tmp_path / "lin0", tmp_path / "ctl.sock"
    cfg = tmp_path / "bus.yaml"
    cfg.write_text("nodes:\n  - {name: a, otp: [0, 0, 3, 0, 0, 0, 0, 0]}\n")
    exe = [sys.executable, "-m", "ecatsim"]
    proc = subprocess.Popen(
        [*exe, "lin", "--pty", str(link), "--config", str(cfg), "--ctl", str(sock)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 10
        while not (link.exists() and sock.exists()) and time.monotonic() < deadline:
            time.sleep(0.05)
        fd = os.open(link, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)

        def exchange(data: bytes, want: int) -> bytes:
            os.write(fd, data)
            out = b""
            end = time.monotonic() + 1.0
            while (
                len(out) < want and select.select([fd], [], [], max(0, end - time.monotonic()))[0]
            ):
                out += os.read(fd, 64)
            time.sleep(0.02)
            return out

        prep = bytes((0x80, 0x81, 0x83, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))
        exchange(header(0x3E), 0)  # wakes the node should it sleep already (N6) ...
        time.sleep(0.15)  # ... and, as LIN masters do after a wake-up, waits before the next
        exchange(lin_frame(0x3C, prep), 0)
        got = exchange(header(0x3D), 9)
        assert got[:8] == bytes((0x83, 0, 0, 0, 0x80, 0x02, 0, 0xFF))
        status = subprocess.run(
            [*exe, "ctl", "--socket", str(sock), "status"], capture_output=True, text=True
        )
        assert status.returncode == 0, status.stderr
        lines = status.stdout.splitlines()  # the door's line, then a table of nodes
        assert lines[0].startswith("lin: pty") and lines[2].split()[:4] == [
            "a",
            "3",
            "Stopped",
            "0",
        ]
        os.close(fd)
    finally:
        proc.terminate()
        out = proc.communicate(timeout=10)[0].decode()
    assert proc.returncode == 0, out
    assert not link.exists()


def test_segment_file_serves_lin_beside_ethercat(tmp_path: Path) -> None:
    """``ecatsim run`` with ``lin:`` in the segment file: one daemon, both buses."""
    seg = tmp_path / "seg.yaml"
    seg.write_text(
        "slaves:\n  - device: echo\nlin:\n  pty: lin0\n  nodes:\n"
        "    - {name: a, otp: [0, 0, 3, 0, 0, 0, 0, 0]}\n"
    )
    link, sock = tmp_path / "lin0", tmp_path / "ctl.sock"
    exe = [sys.executable, "-m", "ecatsim"]
    proc = subprocess.Popen(
        [*exe, "run", "--udp", "127.0.0.1:0", "--config", str(seg), "--ctl", str(sock), "--no-rt"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + 10
        while not (link.exists() and sock.exists()) and time.monotonic() < deadline:
            time.sleep(0.05)
        fd = os.open(link, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        os.write(fd, header(0x3E))  # wake-up; a LIN master then waits 100-150 ms
        time.sleep(0.15)
        os.write(fd, lin_frame(0x3C, bytes((0x80, 0x80, 0x83, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))))
        time.sleep(0.05)
        os.write(fd, header(0x3D))
        got = b""
        while len(got) < 9 and select.select([fd], [], [], 1.0)[0]:
            got += os.read(fd, 64)
        assert got[:8] == bytes((0x83, 0, 0, 0x80, 0xFF, 0xFF, 0xFF, 0xFF))  # GetActualPos
        os.close(fd)
        status = subprocess.run(
            [*exe, "ctl", "--socket", str(sock), "status"], capture_output=True, text=True
        )
        assert "0x0000   INIT" in status.stdout and "lin: pty" in status.stdout, status.stdout
    finally:
        proc.terminate()
        out = proc.communicate(timeout=10)[0].decode()
    assert proc.returncode == 0, out
