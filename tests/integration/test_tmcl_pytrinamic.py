"""pytrinamic (pinned in requirements-test.lock) drives the emulated TMCM-1311 over
``tcp://`` (its socket_serial_tmcl interface) and ``pty:`` (its serial_tmcl interface).

In-process tests run the door in a thread on a manual clock, so a ramp of seconds takes
no wall time; the subprocess tests run ``ecatsim tmcl`` itself on the real clock. None
needs root.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest
from pytrinamic.connections import SerialTmclInterface, SocketTmclInterface
from pytrinamic.modules import TMCM1311
from pytrinamic.tmcl import TMCLReplyStatusError

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import ModuleConfig
from ecatsim.tmcl.motor import Mechanics, Switches
from tests.support.tmcl import Served, served

AP = TMCM1311._MotorTypeA.AP


@pytest.fixture(autouse=True)
def _integration_needs_root() -> None:
    """These tests need no root (overrides the directory's fixture)."""


@pytest.fixture(params=["tcp", "pty"])
def srv(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Served]:
    listen = ["tcp://127.0.0.1:0"] if request.param == "tcp" else [f"pty:{tmp_path / 'tty'}"]
    with served(listen=listen) as s:
        yield s


def interface(srv: Served) -> SocketTmclInterface | SerialTmclInterface:
    """pytrinamic's socket_serial_tmcl for tcp://, serial_tmcl for pty:."""
    if srv.door.listeners:
        return SocketTmclInterface(srv.url)
    pty = srv.door.status()["listen"][0].removeprefix("pty:")
    return SerialTmclInterface(pty, timeout_s=5)


@pytest.fixture(params=["tcp", "pty"])
def lines(request: pytest.FixtureRequest, tmp_path: Path) -> list[str]:
    """The listen URL of one test, once for each transport."""
    if request.param == "tcp":
        return ["tcp://127.0.0.1:0"]
    return [f"pty:{tmp_path / 'tty'}"]


@pytest.fixture
def module(srv: Served) -> Iterator[TMCM1311]:
    iface = interface(srv)
    try:
        yield TMCM1311(iface)
    finally:
        iface.close()


def test_version_string_and_binary(srv: Served, module: TMCM1311) -> None:
    assert module.connection.get_version_string() == "1311V111"
    reply = module.connection.send(136, 1, 0, 0)
    assert (reply.status, reply.value) == (100, 0x051F0B01)


def test_mvp_ramp_takes_time_and_ends_exactly_on_target(srv: Served, module: TMCM1311) -> None:
    motor = module.motors[0]
    motor.set_axis_parameter(AP.MaxVelocity, 51200)
    motor.set_axis_parameter(AP.MaxAcceleration, 102400)
    module.move_to(0, 100_000)
    assert motor.get_position_reached() == 0
    srv.advance(1.0)
    middle = motor.actual_position
    assert 0 < middle < 100_000
    assert motor.get_position_reached() == 0
    assert motor.actual_velocity == 51200
    # 0.5 s up, 100000 - 25600 steps at full speed (1.453 s), 0.5 s down: 2.453 s
    srv.advance(1.4)
    assert motor.get_position_reached() == 0
    srv.advance(0.06)
    assert motor.get_position_reached() == 1
    assert motor.actual_position == 100_000
    assert motor.actual_velocity == 0
    module.move_by(0, -30_000)
    srv.advance(3.0)
    assert motor.actual_position == 70_000
    assert motor.target_position == 70_000


def test_ror_velocity_read_back_by_gap3_then_mst(srv: Served, module: TMCM1311) -> None:
    motor = module.motors[0]
    motor.set_axis_parameter(AP.MaxAcceleration, 50_000)
    module.rotate(0, 40_000)
    srv.advance(0.4)
    assert 0 < motor.actual_velocity < 40_000
    srv.advance(0.5)
    assert motor.actual_velocity == 40_000
    assert motor.get_axis_parameter(AP.RampMode) == 1
    module.rotate(0, -12_345)  # ROL is ROR with a negative speed in pytrinamic
    srv.advance(2.0)
    assert motor.actual_velocity == -12_345
    before = motor.actual_position
    module.stop(0)
    srv.advance(0.3)
    assert motor.actual_velocity == 0
    assert motor.get_axis_parameter(AP.TargetVelocity, signed=True) == 0
    assert motor.actual_position < before


def test_user_variables_sgp_ggp(srv: Served, module: TMCM1311) -> None:
    module.set_global_parameter(42, 2, -123_456)
    module.set_global_parameter(200, 2, 7)
    assert module.get_global_parameter(42, 2, signed=True) == -123_456
    assert module.get_global_parameter(200, 2) == 7
    assert module.get_global_parameter(TMCM1311.GP0.serialAddress, 0) == 1
    assert module.get_global_parameter(TMCM1311.GP0.serialHostAddress, 0) == 2


def test_errors_reach_pytrinamic_as_status(srv: Served, module: TMCM1311) -> None:
    with pytest.raises(TMCLReplyStatusError) as exc:
        module.set_axis_parameter(AP.MaxCurrent, 0, 256)
    assert exc.value.status_code == 4
    with pytest.raises(TMCLReplyStatusError) as exc:
        module.get_axis_parameter(99, 0)
    assert exc.value.status_code == 3
    with pytest.raises(TMCLReplyStatusError) as exc:
        module.connection.send(200, 0, 0, 0)
    assert exc.value.status_code == 2


def test_stap_persists_across_a_restart_unstored_values_revert(
    tmp_path: Path, lines: list[str]
) -> None:
    eeprom = tmp_path / "tmcm.json"
    with served(eeprom=eeprom, listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        m.set_axis_parameter(AP.MaxVelocity, 0, 77_777)
        m.store_axis_parameter(AP.MaxVelocity, 0)
        m.set_axis_parameter(AP.MaxAcceleration, 0, 12_345)  # not stored
        m.set_global_parameter(3, 2, 99)
        m.store_global_parameter(3, 2)
        m.set_global_parameter(4, 2, 98)  # not stored
        iface.close()
    with served(eeprom=eeprom, listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        assert m.get_axis_parameter(AP.MaxVelocity, 0) == 77_777
        assert m.get_axis_parameter(AP.MaxAcceleration, 0) == 51_200
        assert m.get_global_parameter(3, 2) == 99
        assert m.get_global_parameter(4, 2) == 0
        iface.close()


def test_reference_search_finds_the_home_switch(lines: list[str]) -> None:
    sw = Switches(left=-200_000, right=200_000, home=30_000, home_width=2560)
    with served([ModuleConfig(switches=sw)], listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        motor = m.motors[0]
        motor.set_axis_parameter(AP.ReferenceSearchMode, 7)  # home, positive direction
        motor.set_axis_parameter(AP.ReferenceSearchSpeed, 25_600)
        motor.set_axis_parameter(AP.ReferenceSwitchSpeed, 2_560)
        iface.reference_search(0, 0)
        s.advance(0.5)
        assert iface.reference_search(2, 0) == 0  # 0: the search is running (§5.7.13)
        s.advance(8.0)
        assert iface.reference_search(2, 0) != 0
        assert motor.actual_position == 0
        assert motor.get_axis_parameter(AP.HomeSwitch) == 1
        rotor = s.in_loop(lambda: s.door.modules[0].axis.rotor)
        assert abs(rotor - 30_000) < 30  # the middle of the home switch, within a step
        iface.close()


def test_closed_loop_positioning_holds_the_encoder_deviation_under_a_load_step(
    lines: list[str],
) -> None:
    with served([ModuleConfig(mech=Mechanics(load_inertia=1e-4))], listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        motor = m.motors[0]
        motor.set_axis_parameter(AP.MaxCurrent, 200)
        motor.set_axis_parameter(AP.MaxPositionEncoderDeviation, 2_000)
        motor.set_axis_parameter(AP.ClosedLoopMode, 1)
        s.advance(0.2)
        assert motor.get_axis_parameter(AP.CLInitFlag) == 1
        motor.set_axis_parameter(AP.MaxVelocity, 40_000)
        motor.set_axis_parameter(AP.MaxAcceleration, 80_000)
        m.move_to(0, 40_000)  # encoder steps: one revolution
        s.advance(0.6)
        s.ctl("load", "1", "0.4")  # a load step: 40 % of the holding torque
        worst = 0
        for _ in range(30):
            s.advance(0.05)
            worst = max(worst, abs(motor.get_axis_parameter(AP.CLPositionError, signed=True)))
        assert motor.get_position_reached() == 1
        assert abs(motor.actual_position - 40_000) <= 50  # the position window (134)
        assert 0 < worst < 2_000
        assert motor.get_axis_parameter(AP.ExtendedErrorFlags) == 0  # no deviation
        iface.close()


def _closed_loop(s: Served, m: TMCM1311) -> None:
    """Closed loop on (§8.1) with a deviation limit, initialised."""
    motor = m.motors[0]
    motor.set_axis_parameter(AP.MaxPositionEncoderDeviation, 2_000)
    motor.set_axis_parameter(AP.ClosedLoopMode, 1)
    s.advance(0.2)
    assert motor.get_axis_parameter(AP.CLInitFlag) == 1


def _rotor(s: Served) -> float:
    rotor: float = s.in_loop(lambda: s.door.modules[0].axis.rotor)
    return rotor


def test_closed_loop_setting_the_position_at_rest_leaves_the_rotor_still(
    lines: list[str],
) -> None:
    """SAP 1 ("for reference point setting", §6) and SAP 209 change the coordinates, not
    the rotor; MVP then reaches its targets (AP 8) in the new coordinates (decision T26)."""
    with served(listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        motor = m.motors[0]
        _closed_loop(s, m)
        m.move_to(0, 40_000)  # encoder steps: one revolution of the 40000-step encoder
        s.advance(2.5)
        assert motor.get_position_reached() == 1
        at = _rotor(s)
        assert abs(at - 51_200) < 3  # one revolution: 51200 motor microsteps
        motor.set_axis_parameter(AP.ActualPosition, 0)
        s.advance(1.0)
        assert motor.actual_position == 0
        assert motor.get_position_reached() == 1
        assert abs(_rotor(s) - at) < 3  # still: not one step
        motor.set_axis_parameter(AP.EncoderPosition, -5_000)
        s.advance(1.0)
        assert motor.actual_position == -5_000
        assert motor.get_axis_parameter(AP.EncoderPosition, signed=True) == -5_000
        assert motor.get_position_reached() == 1
        assert abs(_rotor(s) - at) < 3
        m.move_to(0, 15_000)  # 20000 encoder steps on: half a revolution
        s.advance(0.1)
        assert motor.get_position_reached() == 0
        s.advance(2.0)
        assert motor.get_position_reached() == 1
        assert abs(motor.actual_position - 15_000) <= 50  # the position window (134)
        assert abs(_rotor(s) - at - 25_600) < 3
        # closed loop off and on again: the coordinates go on, the rotor stays
        motor.set_axis_parameter(AP.ClosedLoopMode, 0)
        s.advance(0.2)
        assert motor.actual_position == 19_200  # 15000 encoder steps in microsteps
        motor.set_axis_parameter(AP.ClosedLoopMode, 1)
        s.advance(0.5)
        assert motor.actual_position == 15_000
        m.move_to(0, 0)
        s.advance(2.5)
        assert motor.get_position_reached() == 1
        assert abs(_rotor(s) - at - 6_400) < 3  # 0 is now 5000 encoder steps further on
        assert motor.get_axis_parameter(AP.ExtendedErrorFlags) == 0
        iface.close()


def test_closed_loop_reference_search_ends_at_zero_on_the_switch(lines: list[str]) -> None:
    """RFS mode 1 in closed loop: position 0 at the left switch, moves reach after it."""
    with served([ModuleConfig(switches=Switches(left=-30_000))], listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        motor = m.motors[0]
        _closed_loop(s, m)
        motor.set_axis_parameter(AP.ReferenceSearchMode, 1)
        motor.set_axis_parameter(AP.MaxAcceleration, 512_000)
        motor.set_axis_parameter(AP.ReferenceSearchSpeed, 51_200)
        motor.set_axis_parameter(AP.ReferenceSwitchSpeed, 5_120)
        iface.reference_search(0, 0)
        s.advance(0.3)
        assert iface.reference_search(2, 0) == 0  # running
        s.advance(3.0)
        assert iface.reference_search(2, 0) != 0
        assert motor.get_position_reached() == 1
        assert motor.actual_position == 0
        assert abs(_rotor(s) - (-30_000)) < 3  # the switching point of the left switch
        m.move_to(0, 10_000)
        s.advance(2.0)
        assert motor.get_position_reached() == 1
        assert abs(motor.actual_position - 10_000) <= 50
        assert abs(_rotor(s) - (-30_000 + 12_800)) < 3
        assert motor.get_axis_parameter(AP.ExtendedErrorFlags) == 0
        iface.close()


def _search(s: Served, m: TMCM1311, mode: int, seconds: float) -> tuple[float, float]:
    """Run RFS ``mode`` for ``seconds`` of simulated time in 50 ms slices; the rotor's
    lowest and highest position on the way."""
    motor = m.motors[0]
    motor.set_axis_parameter(AP.ReferenceSearchMode, mode)
    motor.set_axis_parameter(AP.MaxAcceleration, 512_000)  # soft stops of 2560 steps
    motor.set_axis_parameter(AP.ReferenceSearchSpeed, 51_200)
    motor.set_axis_parameter(AP.ReferenceSwitchSpeed, 5_120)
    m.connection.reference_search(0, 0)
    low = high = _rotor(s)
    for _ in range(round(seconds / 0.05)):
        s.advance(0.05)
        r = _rotor(s)
        low, high = min(low, r), max(high, r)
    return low, high


def test_reference_search_133_and_135_inverted_home_finish_at_its_edge(
    lines: list[str],
) -> None:
    """Modes 5 and 7 + 128 (§9.1.1: the home switch inverted): the home level is active
    everywhere but over the switch (here 29000-31000 motor microsteps), so the search
    finds where it becomes active in the search direction and calibrates that switching
    point (§9: released and re-entered slowly, the middle of the two). Mode 133 searches
    in negative direction, turns at the left stop switch and finds the edge at 31000; 135
    searches in positive direction and finds it too (decision T27). Neither drives through
    a stop switch."""
    sw = Switches(left=-20_000, right=60_000, home=30_000, home_width=2_000)
    for mode in (133, 135):
        with served([ModuleConfig(switches=sw)], listen=lines) as s:
            iface = interface(s)
            m = TMCM1311(iface)
            motor = m.motors[0]
            low, high = _search(s, m, mode, 12.0)
            assert iface.reference_search(2, 0) != 0, mode  # finished
            assert motor.actual_position == 0
            assert abs(_rotor(s) - 31_000) < 3, mode
            assert motor.get_position_reached() == 1
            assert low > -20_000 - 4_000 and high < 60_000, (mode, low, high)
            # AP 9 reads the input itself: on over the switch, off beyond its edge
            m.move_to(0, -1_000)
            s.advance(0.5)
            assert motor.get_axis_parameter(AP.HomeSwitch) == 1
            m.move_to(0, 1_000)
            s.advance(0.5)
            assert motor.get_axis_parameter(AP.HomeSwitch) == 0
            iface.close()


def test_reference_search_133_without_a_home_switch_stops_at_the_right_switch(
    lines: list[str],
) -> None:
    """Mode 133 where no home switch is fitted: it turns at the left stop switch, and the
    right one ends the search there instead of being driven through (decision T27)."""
    sw = Switches(left=-20_000, right=40_000)
    with served([ModuleConfig(switches=sw)], listen=lines) as s:
        iface = interface(s)
        m = TMCM1311(iface)
        low, high = _search(s, m, 133, 6.0)
        assert iface.reference_search(2, 0) != 0  # over
        assert m.motors[0].actual_velocity == 0
        assert -24_000 < low <= -20_000
        assert 40_000 <= high < 44_000  # stopped at the right switch with the ramp (149)
        iface.close()


class _BytewiseSocket:
    """pytrinamic's socket, but every telegram goes out one byte per TCP segment, 50 ms of
    the door's clock apart, each byte read by the door before the next is sent."""

    def __init__(self, sock: socket.socket, s: Served) -> None:
        self.sock = sock
        self.s = s

    def sendall(self, data: bytes) -> None:
        for byte in data:
            before = self.s.door.frames
            self.sock.sendall(bytes([byte]))
            self._wait_read(before)
            self.s.advance(0.05)

    def _wait_read(self, frames_before: int) -> None:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            pending = self.s.in_loop(
                lambda: sum(st.framer.pending for st in self.s.door.lines.values())
            )
            if pending or self.s.door.frames != frames_before:
                return
            time.sleep(0.002)
        raise AssertionError("the door did not read the byte")

    def __getattr__(self, name: str) -> object:
        return getattr(self.sock, name)


def test_tcp_telegram_in_bytes_50_ms_apart_is_answered() -> None:
    """Over TCP a telegram has no timing (decision T25): 9 bytes, each in its own
    segment 50 ms apart (the serial line's 20 ms pause of T3 would drop them), are one
    telegram; pytrinamic gets its replies."""
    with served(listen=["tcp://127.0.0.1:0"]) as s:
        iface = SocketTmclInterface(s.url)
        raw = iface._socket
        assert raw is not None
        raw.settimeout(5)  # a lost telegram fails the test instead of hanging it
        iface._socket = _BytewiseSocket(raw, s)
        try:
            m = TMCM1311(iface)
            t0 = s.clock.now_ns()
            assert iface.get_version_string() == "1311V111"
            assert s.clock.now_ns() - t0 == 9 * 50_000_000
            m.motors[0].set_axis_parameter(AP.MaxVelocity, 12_345)
            assert m.motors[0].get_axis_parameter(AP.MaxVelocity) == 12_345
            assert s.in_loop(lambda: s.door.modules[0].errors) == 0
        finally:
            iface._socket = raw
            iface.close()


def test_pty_keeps_the_serial_pause(tmp_path: Path) -> None:
    """On a serial line (pty) the 20 ms pause still drops a partial telegram (T3)."""
    with served(listen=[f"pty:{tmp_path / 'tty'}"]) as s:
        pty = s.door.status()["listen"][0].removeprefix("pty:")
        fd = os.open(pty, os.O_RDWR | os.O_NOCTTY)
        try:
            tty.setraw(fd)
            frame = P.encode_command(1, P.Command(P.GAP, 4, 0, 0))
            os.write(fd, frame[:4])
            deadline = time.monotonic() + 5
            while s.in_loop(lambda: sum(x.framer.pending for x in s.door.lines.values())) < 4:
                assert time.monotonic() < deadline
                time.sleep(0.002)
            s.advance(0.05)
            os.write(fd, frame)  # the stale 4 bytes are dropped: this one is answered
            reply = b""
            while len(reply) < 9:
                reply += os.read(fd, 9 - len(reply))
            assert reply[:4] == bytes([2, 1, P.OK, P.GAP])
        finally:
            os.close(fd)


# ----------------------------------------------------------------- the real command


def _start(tmp_path: Path, *args: str) -> subprocess.Popen[bytes]:
    env = dict(os.environ, XDG_RUNTIME_DIR=str(tmp_path))
    return subprocess.Popen(
        [sys.executable, "-m", "ecatsim", "tmcl", "--ctl", str(tmp_path / "ctl.sock"), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env=env,
    )


def _stop(proc: subprocess.Popen[bytes]) -> str:
    proc.terminate()
    out, _ = proc.communicate(timeout=10)
    assert proc.returncode == 0, out.decode()
    return out.decode()


def _wait_for(pred: object, proc: subprocess.Popen[bytes], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if callable(pred) and pred():
            return
        if proc.poll() is not None:
            raise AssertionError(proc.stdout.read().decode() if proc.stdout else "exited")
        time.sleep(0.05)
    raise AssertionError("ecatsim tmcl did not come up")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _connects(port: int) -> bool:
    import socket

    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
    except OSError:
        return False
    return True


def test_ecatsim_tmcl_over_tcp_and_pty(tmp_path: Path) -> None:
    port = _free_port()
    pty = tmp_path / "tmcm1311"
    proc = _start(tmp_path, "--listen", f"tcp://127.0.0.1:{port}", "--listen", f"pty:{pty}")
    try:
        _wait_for(lambda: pty.exists() and _connects(port), proc)
        serial = SerialTmclInterface(str(pty), timeout_s=2)
        sock = SocketTmclInterface(f"127.0.0.1:{port}")
        try:
            over_pty, over_tcp = TMCM1311(serial), TMCM1311(sock)
            assert serial.get_version_string() == "1311V111"
            over_pty.set_axis_parameter(AP.MaxAcceleration, 0, 1_000_000)
            over_pty.set_axis_parameter(AP.MaxVelocity, 0, 200_000)
            over_pty.move_to(0, 20_000)  # 0.1 s at speed after 0.2 s ramps: done in 0.5 s
            assert over_tcp.get_axis_parameter(AP.TargetPosition, 0) == 20_000
            deadline = time.monotonic() + 5
            while over_tcp.motors[0].get_position_reached() != 1:
                assert time.monotonic() < deadline
                time.sleep(0.05)
            assert over_pty.motors[0].actual_position == 20_000
            over_tcp.rotate(0, 5000)
            time.sleep(0.1)
            assert over_pty.motors[0].actual_velocity == 5000
            over_tcp.stop(0)
            over_pty.set_global_parameter(10, 2, 4242)
            assert over_tcp.get_global_parameter(10, 2) == 4242
            ctl = [sys.executable, "-m", "ecatsim", "ctl", "--socket", str(tmp_path / "ctl.sock")]
            fault = subprocess.run(
                [*ctl, "door", "tmcl", "fault", "1", "overtemperature", "on"],
                capture_output=True,
                text=True,
                timeout=10,
            )
            assert fault.returncode == 0, fault.stderr
            assert over_tcp.get_axis_parameter(AP.DriverErrorFlags, 0) & 2
            status = subprocess.run([*ctl, "status"], capture_output=True, text=True, timeout=10)
            lines = status.stdout.splitlines()  # the door's line, then a table of modules
            assert lines[0].startswith("tmcl: listen") and "overtemperature" in lines[2].split()
        finally:
            serial.close()
            sock.close()
    finally:
        out = _stop(proc)
    assert "ready" in out
    assert not pty.exists()


def test_ecatsim_tmcl_eeprom_survives_restart(tmp_path: Path) -> None:
    port = _free_port()
    eeprom = tmp_path / "eeprom.json"
    args = ("--listen", f"tcp://127.0.0.1:{port}", "--eeprom", str(eeprom))
    for run in range(2):
        proc = _start(tmp_path, *args)
        try:
            _wait_for(lambda: _connects(port), proc)
            sock = SocketTmclInterface(f"127.0.0.1:{port}")
            m = TMCM1311(sock)
            if run == 0:
                m.set_axis_parameter(AP.MaxCurrent, 0, 99)
                m.store_axis_parameter(AP.MaxCurrent, 0)
                m.set_axis_parameter(AP.StandbyCurrent, 0, 50)
            else:
                assert m.get_axis_parameter(AP.MaxCurrent, 0) == 99
                assert m.get_axis_parameter(AP.StandbyCurrent, 0) == 8
            sock.close()
        finally:
            _stop(proc)
