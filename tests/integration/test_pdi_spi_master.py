"""External slave firmware over the PDI SPI socket, with pysoem as the master.

The project's example firmware (tools/spi_firmware.py) serves the first slave over its
socket; the second slave runs ecatsim's own firmware. Ref: TMC8460 §3.5, §5.40.
"""

from __future__ import annotations

import random
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pysoem
import pytest

from tests.integration.test_esc_master import to_op

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]
RX_TIMEOUT_US = 50_000


def segment(tmp_path: Path, sock: Path) -> Path:
    cfg = tmp_path / "segment.yaml"
    cfg.write_text(
        "slaves:\n"
        f"  - {{device: tmc8670, firmware: external, pdi_socket: {sock}}}\n"
        "  - {device: echo}\n"
    )
    return cfg


def start_firmware(sock: Path) -> subprocess.Popen[bytes]:
    """The example firmware, connected (as a board's MCU is up before the master starts:
    the AL control register takes one request until the firmware has read it, §5.20)."""
    fw = subprocess.Popen(
        [sys.executable, str(ROOT / "tools" / "spi_firmware.py"), str(sock)],
        stdout=subprocess.PIPE,
    )
    assert fw.stdout is not None
    assert fw.stdout.readline().startswith(b"spi_firmware: serving")
    return fw


def cycles(master: Any, n: int) -> None:
    for _ in range(n):
        master.send_processdata()
        master.receive_processdata(RX_TIMEOUT_US)
        time.sleep(0.001)


def test_external_firmware_to_op_copying_outputs_to_inputs(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock = tmp_path / "pdi.sock"
    daemon_factory("--config", str(segment(tmp_path, sock)))
    fw = start_firmware(sock)
    try:
        master = master_factory()
        assert master.config_init() == 2
        s0 = master.slaves[0]
        assert (s0.man, s0.id) == (0x286, 8670)
        # nothing but the external firmware moved the first slave to PREOP
        assert master.state_check(pysoem.PREOP_STATE, 2_000_000) == pysoem.PREOP_STATE
        to_op(master)
        master.read_state()
        assert [s.state for s in master.slaves] == [pysoem.OP_STATE] * 2
        # the SII's PDOs (the firmware aborts the PDO assignment objects): 12 out, 17 in
        assert (len(s0.output), len(s0.input)) == (12, 17)
        pattern = bytes(range(0x31, 0x3D))
        s0.output = pattern
        for _ in range(200):
            cycles(master, 1)
            if s0.input[:12] == pattern:
                break
        assert s0.input == pattern + bytes(5)
        assert s0.sdo_read(0x1000, 0) == b"\x92\x01\x02\x00"
        assert s0.sdo_read(0x1600, 2) == b"\x20\x02\x00\x70"
        with pytest.raises(pysoem.SdoError) as err:
            s0.sdo_read(0x1018, 1)
        assert err.value.abort_code == 0x06020000
        assert s0._fprd(0x0110, 2)[0] & 0x02  # PDI watchdog: reloaded
        assert s0._fprd(0x030D, 2) == b"\x00\x00"  # no SPI interface error
        # the firmware stops: after 0x0410 x 100 us (100 ms) the PDI watchdog expires (it may
        # have expired once already, while the firmware was starting)
        expiries = s0._fprd(0x0443, 1)[0]
        fw.kill()
        fw.wait()
        cycles(master, 150)
        assert not s0._fprd(0x0110, 2)[0] & 0x02
        assert s0._fprd(0x0443, 1)[0] == expiries + 1
        # the other slave does not care
        assert master.slaves[1].state_check(pysoem.OP_STATE, 50_000) == pysoem.OP_STATE
    finally:
        fw.kill()
        fw.wait()


def test_100k_random_frames_on_the_socket_then_op(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    """Random chip-select frames (random commands, addresses and data) never stop the
    daemon; the other slave keeps its state, and the firmware that connects next brings
    its slave to OP."""
    sock = tmp_path / "pdi.sock"
    daemon = daemon_factory("--config", str(segment(tmp_path, sock)))
    rng = random.Random(20)
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    c.connect(str(sock))
    want = 0
    batch = bytearray()
    for i in range(100_000):
        n = rng.choice((0, 1, 2, 3, 4, 5, 8, rng.randrange(0, 64)))
        mosi = bytes(rng.getrandbits(8) for _ in range(n))
        if n >= 2 and mosi[1] & 7 == 4 and mosi[0] < 0x80:
            # a write below 0x1000 would be a firmware misconfiguring its own chip
            mosi = mosi[:1] + bytes([mosi[1] & 0xF8]) + mosi[2:]
        batch += struct.pack("<H", n) + mosi
        want += n
        if i % 500 == 499:
            c.sendall(batch)
            batch.clear()
            got = 0
            while got < want:
                got += len(c.recv(65536))
            want = 0
    c.close()
    assert daemon.alive()
    fw = start_firmware(sock)
    try:
        master = master_factory()
        assert master.config_init() == 2
        to_op(master)
        master.read_state()
        assert [s.state for s in master.slaves] == [pysoem.OP_STATE] * 2
    finally:
        fw.kill()
        fw.wait()


def system_time_frame(c: socket.socket) -> int:
    """0x0910 over the PDI SPI: 3-byte address, read with the wait state byte, 8 bytes."""
    mosi = bytes([0x0910 >> 5, ((0x0910 & 0x1F) << 3) | 6, 3 << 2, 0xFF]) + bytes(7) + b"\xff"
    c.sendall(struct.pack("<H", len(mosi)) + mosi)
    got = b""
    while len(got) < len(mosi):
        got += c.recv(len(mosi) - len(got))
    return int.from_bytes(got[4:], "little")


def test_firmware_reads_the_running_system_time(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    """TMC8460 §5.50.2 Table 95: a PDI read of 0x0910 is the system time latched when its
    first byte is read, with DC unused and with the master's DC running. Two reads about
    1 ms apart differ by the time between them: at least the time from the first answer
    to the second request, at most the time from the first request to the second answer."""
    sock = tmp_path / "pdi.sock"
    daemon_factory("--config", str(segment(tmp_path, sock)))
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    c.connect(str(sock))

    def two_reads() -> tuple[int, int, int]:
        t0 = time.monotonic_ns()
        a = system_time_frame(c)
        t1 = time.monotonic_ns()
        time.sleep(0.001)
        t2 = time.monotonic_ns()
        b = system_time_frame(c)
        t3 = time.monotonic_ns()
        return b - a, t2 - t1, t3 - t0

    try:
        delta, inner, outer = two_reads()
        assert 1_000_000 <= inner <= delta <= outer  # DC off: the local clock runs anyway
        assert delta < 50_000_000
        master = master_factory()
        assert master.config_init() == 2
        master.config_dc()  # the master's DC: offsets, delays, the time loop
        delta, inner, outer = two_reads()
        assert 1_000_000 <= inner <= delta + 100_000 and delta <= outer + 100_000
        # the same system time the master reads (latched at its frame, a little earlier)
        ecat = int.from_bytes(master.slaves[0]._fprd(0x0910, 8), "little")
        assert 0 < system_time_frame(c) - ecat < 100_000_000
    finally:
        c.close()
