"""The MFC CTRL SPI on a socket (TMC8460 §3.6): a microcontroller drives the step/dir unit
of the MFCIO block while the EtherCAT master only watches SD_SC in its inputs."""

from __future__ import annotations

import socket
import struct
from pathlib import Path

import pytest

from ecatsim.clock import ManualClock
from ecatsim.doors.from_config import build_doors
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import load_segment, parse_segment
from ecatsim.mfcio.stepdir import sr_for
from tests.support.mfcio import mb0, mb1
from tests.support.spisock import spi_frame
from tests.support.tinymaster import TinyMaster

ROOT = Path(__file__).resolve().parents[2]
STATION = 0x1001
#: step/dir registers configured for SPI access (bit 4 = 0), everything else for ECAT
SPI_SD = "{default: 0x10, registers: {SD_SR: 0x00, SD_ST: 0x00, SD_CFG: 0x00, SD_DLY: 0x00}}"


def write_cmd(reg: int, data: bytes) -> bytes:
    """A 2-byte-address write of register ``reg`` from byte 0 (§3.6, §3.5.1 command 4)."""
    addr = reg << 4
    return bytes([addr >> 5, ((addr & 0x1F) << 3) | 4]) + data


def read_cmd(reg: int, n: int) -> bytes:
    """A read with wait state of ``n`` bytes of register ``reg`` (command 3)."""
    addr = reg << 4
    return bytes([addr >> 5, ((addr & 0x1F) << 3) | 3, 0xFF]) + bytes(n - 1) + b"\xff"


@pytest.fixture
def rig(tmp_path: Path):  # type: ignore[no-untyped-def]
    desc = (ROOT / "config" / "tmc8460.yaml").read_text()
    desc = desc.replace("mfcio:\n  default: 0x10", f"mfcio: {SPI_SD}\n  _was: 0x10", 1)
    desc = "\n".join(line for line in desc.splitlines() if "_was:" not in line)
    (tmp_path / "desc.yaml").write_text(desc)
    sock = tmp_path / "mfc.sock"
    (tmp_path / "seg.yaml").write_text(
        "slaves:\n"
        f"  - {{device: tmc8460, description: desc.yaml, mfc_socket: {sock}, mfcio: "
        "{stepper: {full_steps: 200, microsteps: 16, microsteps_per_pulse: 1}}}\n"
    )
    cfg = load_segment(tmp_path / "seg.yaml")
    clock = ManualClock(1_000_000_000)
    seg = build_segment(cfg, clock)
    host = build_doors(cfg, seg)
    assert host is not None and list(host.doors) == ["mfc0"]
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    c.connect(str(sock))
    host.serve()

    def spi(mosi: bytes) -> bytes:
        return spi_frame(c, host, mosi)

    yield seg, clock, spi
    c.close()
    host.close()


def test_the_mcu_moves_the_stepper_the_master_watches(rig) -> None:  # type: ignore[no-untyped-def]
    seg, clock, spi = rig
    m = TinyMaster(seg, clock)
    m.apwr(0, 0x0010, struct.pack("<H", STATION))
    assert m.fprd(STATION, 0x0580 + 12, 1).data == b"\x00"  # SD_SR: SPI access
    m.fpwr(STATION, 0x0810, struct.pack("<HHBBBB", 0x4000, 96, 0x64, 0, 1, 0))
    m.fpwr(STATION, 0x0818, struct.pack("<HHBBBB", 0x4800, 36, 0x20, 0, 1, 0))
    m.fpwr(STATION, 0x0600, struct.pack("<IHBBHBBB3x", 0, 96, 0, 7, 0x4000, 0, 2, 1))
    m.fpwr(STATION, 0x0610, struct.pack("<IHBBHBBB3x", 96, 36, 0, 7, 0x4800, 0, 1, 1))
    for st in (2, 4, 8):
        m.fpwr(STATION, 0x0120, struct.pack("<H", st))
    assert m.u16(STATION, 0x0130) == 8

    def cycles(n: int, **values: int) -> dict[str, int]:
        out: dict[str, int] = {}
        for _ in range(n):
            clock.advance(1_000_000)
            r = m.lrw(0, mb0(**values) + bytes(36))
            assert r.wkc == 3
            out = mb1(r.data[96:])
        return out

    # the master's outputs try to start a move: these registers belong to the SPI now
    assert cycles(5, SD_SR=sr_for(10_000), SD_ST=500, SD_CFG=1)["SD_SC"] == 0
    # the microcontroller starts 2000 steps at 10 kHz over the MFC CTRL SPI
    assert spi(write_cmd(12, struct.pack("<I", sr_for(10_000)))) == bytes(6)
    assert spi(write_cmd(14, struct.pack("<I", 2000))) == bytes(6)
    assert spi(write_cmd(17, b"\x01")) == bytes(3)
    assert cycles(250)["SD_SC"] == 2000  # 200 ms of steps, watched through MB1
    assert spi(read_cmd(13, 4))[3:] == struct.pack("<I", 2000)  # SD_SC over SPI too


def test_bad_frames_are_counted_and_the_socket_stays(rig) -> None:  # type: ignore[no-untyped-def]
    _, _, spi = rig
    assert spi(b"\x00\x05") == bytes(2)  # a reserved command
    assert spi(b"\x01") == bytes(1)  # cut inside the address
    assert spi(write_cmd(12, struct.pack("<I", 0x12345678))) == bytes(6)
    assert spi(read_cmd(12, 4))[3:] == struct.pack("<I", 0x12345678)


def test_mfc_socket_is_for_one_tmc8460() -> None:
    with pytest.raises(UserError, match=r"slaves\[0\]\.mfc_socket: one socket, for one device"):
        parse_segment({"slaves": [{"device": "echo", "mfc_socket": "m.sock"}]}, "seg.yaml")
