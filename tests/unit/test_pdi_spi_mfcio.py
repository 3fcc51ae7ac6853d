"""A TMC8460 with MFCIO and a microcontroller on the PDI SPI (TMC8460 §3.1.2): the PDI
socket is served beside the MFCIO block, and the block sees the PDI chip select (§6.4
Table 136 triggers 7/8, §6.11.2 Table 151 WD_CFG bit 1). Decisions M32, M33."""

from __future__ import annotations

import socket
import struct
from pathlib import Path

import pytest

from ecatsim.clock import ManualClock
from ecatsim.doors.from_config import build_doors
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import load_segment
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.pdi_spi.external import ExternalFirmware
from tests.support.mfcio import mb0, mb1
from tests.support.spisock import spi_frame
from tests.support.tinymaster import TinyMaster

ROOT = Path(__file__).resolve().parents[2]
STATION = 0x1001
#: GPO_OUT_VAL taken at PDI chip deselect (8), GPI_IN_VAL sampled at chip select (7)
CONFIG = "{default: 0x10, registers: {GPO_OUT_VAL: 0x18, GPI_IN_VAL: 0x17}}"
NOP = b"\x00\x00"


@pytest.fixture
def board(tmp_path: Path):  # type: ignore[no-untyped-def]
    desc = (ROOT / "config" / "tmc8460.yaml").read_text()
    desc = desc.replace("mfcio:\n  default: 0x10", f"mfcio: {CONFIG}\n  _was: 0x10", 1)
    desc = "\n".join(line for line in desc.splitlines() if "_was:" not in line)
    (tmp_path / "desc.yaml").write_text(desc)
    pdi, mfc = tmp_path / "pdi.sock", tmp_path / "mfc.sock"
    (tmp_path / "seg.yaml").write_text(
        "slaves:\n"
        f"  - {{device: tmc8460, description: desc.yaml, firmware: external,"
        f" pdi_socket: {pdi}, mfc_socket: {mfc}}}\n"
    )
    cfg = load_segment(tmp_path / "seg.yaml")
    clock = ManualClock(1_000_000_000)
    seg = build_segment(cfg, clock)
    host = build_doors(cfg, seg)
    assert host is not None and sorted(host.doors) == ["mfc0", "pdi0"]
    block = seg.firmware[0]
    assert isinstance(block, MfcioBlock) and isinstance(block.mcu, ExternalFirmware)
    c = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    c.connect(str(pdi))
    host.serve()

    def spi(mosi: bytes) -> bytes:
        return spi_frame(c, host, mosi)

    m = TinyMaster(seg, clock)
    m.apwr(0, 0x0010, struct.pack("<H", STATION))
    m.fpwr(STATION, 0x0810, struct.pack("<HHBBBB", 0x4000, 96, 0x64, 0, 1, 0))
    m.fpwr(STATION, 0x0818, struct.pack("<HHBBBB", 0x4800, 36, 0x20, 0, 1, 0))
    m.fpwr(STATION, 0x0600, struct.pack("<IHBBHBBB3x", 0, 96, 0, 7, 0x4000, 0, 2, 1))
    m.fpwr(STATION, 0x0610, struct.pack("<IHBBHBBB3x", 96, 36, 0, 7, 0x4800, 0, 1, 1))
    for st in (2, 4, 8):
        m.fpwr(STATION, 0x0120, struct.pack("<H", st))
    assert m.u16(STATION, 0x0130) == 8
    yield m, clock, block, spi
    c.close()
    host.close()


def test_the_pdi_socket_is_served_beside_the_mfcio_block(board) -> None:  # type: ignore[no-untyped-def]
    m, _, _, spi = board
    m.apwr(0, 0x3000, b"\x5a\xa5")  # the microcontroller reads the PDRAM over its SPI
    # 3-byte address 0x3000, read with wait state (§3.5.1): A[12:5], A[4:0]|6, A[15:13]|3<<2
    got = spi(bytes([0x80, 0x06, 0x20 | (3 << 2), 0xFF, 0x00, 0xFF]))
    assert got == bytes([0x00, 0x00, 0x00, 0x00, 0x5A, 0xA5])
    assert m.fprd(STATION, 0x030D, 1).data == b"\x00"  # no interface error


def test_pdi_chip_select_and_deselect_move_their_registers(board) -> None:  # type: ignore[no-untyped-def]
    m, clock, block, spi = board

    def cycle(**values: int) -> dict[str, int]:
        clock.advance(1_000_000)
        r = m.lrw(0, mb0(**values) + bytes(36))
        assert r.wkc == 3
        return mb1(r.data[96:])

    for _ in range(3):
        cycle(GPO_OUT_VAL=0x00A5)
    assert block.unit_value(33) == 0  # trigger 8: waits for a PDI chip deselect
    block.set_gpio_input(3, 1, clock.now_ns())
    assert cycle(GPO_OUT_VAL=0x00A5)["GPI_IN_VAL"] == 0  # trigger 7: waits for a chip select
    spi(NOP)
    assert block.unit_value(33) == 0x00A5
    cycle(GPO_OUT_VAL=0x00A5)  # the shadow reaches MB1 at the block's next run
    assert cycle(GPO_OUT_VAL=0x00A5)["GPI_IN_VAL"] == 0x08
    # a chip select without clocks (a frame of no bytes) toggles the line all the same
    cycle(GPO_OUT_VAL=0x0011)
    block.set_gpio_input(3, 0, clock.now_ns())
    spi(b"")
    assert block.unit_value(33) == 0x0011
    cycle(GPO_OUT_VAL=0x0011)
    assert cycle(GPO_OUT_VAL=0x0011)["GPI_IN_VAL"] == 0


@pytest.mark.parametrize("cfg", [0x02, 0x00])
def test_wd_cfg_bit_1_retriggers_on_the_pdi_chip_deselect(board, cfg: int) -> None:  # type: ignore[no-untyped-def]
    """WD_CFG bit 1 cfg_pdi_csn_enable: "Retrigger by positive edge on PDI_SPI_CSN"."""
    m, clock, block, spi = board
    clock.advance(1_000_000)
    m.lrw(0, mb0(WD_TIME=25_000, WD_CFG=cfg) + bytes(36))  # 1 ms of 25 MHz clocks
    for _ in range(10):  # no frames, only PDI accesses every 0.5 ms
        clock.advance(500_000)
        spi(NOP)
    status = block.status(clock.now_ns())
    assert status["wd_active"] is (cfg == 0)
    if cfg:
        assert status["wd_max"] == 12_500  # the longest gap between two deselects
    clock.advance(1_500_000)  # the microcontroller stops
    assert block.status(clock.now_ns())["wd_active"] is True


def test_the_microcontroller_owns_the_esc_events(board) -> None:  # type: ignore[no-untyped-def]
    """Decision M32: with a microcontroller on the PDI the block acknowledges no event for
    it (M25 is for the board without one): the expired process-data watchdog's AL event
    0x0220.6 waits for the microcontroller's read of 0x0440."""
    m, clock, _block, spi = board
    clock.advance(1_000_000)
    assert m.lrw(0, mb0() + bytes(36)).wkc == 3  # SM2 written: the watchdog runs (100 ms)
    clock.advance(150_000_000)
    m.fprd(STATION, 0x0130, 2)  # a frame: the block runs after it
    assert spi(NOP)[0] & 0x40  # the address phase shows the event (§3.5.1)
    assert m.fprd(STATION, 0x0440, 1).data[0] & 0x01 == 0  # expired
    spi(bytes([0x0440 >> 5, ((0x0440 & 0x1F) << 3) | 3, 0xFF, 0xFF]))  # the MCU reads 0x0440
    assert not spi(NOP)[0] & 0x40
