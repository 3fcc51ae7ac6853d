"""The MFCIO block in a segment, driven in process by the tiny master as SOEM would: the
shipped config/tmc8460-mfcio.yaml through SM2 (MB0) and SM3 (MB1), the AL-state gating,
the shadow triggers, the watchdogs and the emergency switch. Ref: TMC8460 §6."""

from __future__ import annotations

import struct
from pathlib import Path

from ecatsim.clock import ManualClock
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import load_segment
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.mfcio.stepdir import sr_for
from tests.support.mfcio import mb0, mb1, s32
from tests.support.tinymaster import TinyMaster

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "config" / "tmc8460-mfcio.yaml"
STATION = 0x1001
CYCLE_NS = 1_000_000
MOVE = {
    "ENC_MODE": 0x18,
    "ENC_CONST": 0x00010000,
    "SD_SR": sr_for(10_000),
    "SD_ST": 2000,
    "SD_CFG": 0x01,
}


class Bench:
    """One TMC8460 MFCIO slave on a manual clock, configured as SOEM configures it."""

    def __init__(self, config: Path = CONFIG) -> None:
        self.clock = ManualClock(1_000_000_000)
        self.seg: Segment = build_segment(load_segment(config), self.clock)
        self.m = TinyMaster(self.seg, self.clock)
        self.values: dict[str, int] = {}
        self.out = mb0()
        self.inputs: dict[str, int] = {}
        m = self.m
        m.apwr(0, 0x0010, struct.pack("<H", STATION))
        m.fpwr(STATION, 0x0120, b"\x02\x00")
        m.fpwr(STATION, 0x0810, struct.pack("<HHBBBB", 0x4000, 96, 0x64, 0, 1, 0))
        m.fpwr(STATION, 0x0818, struct.pack("<HHBBBB", 0x4800, 36, 0x20, 0, 1, 0))
        m.fpwr(STATION, 0x0600, struct.pack("<IHBBHBBB3x", 0, 96, 0, 7, 0x4000, 0, 2, 1))
        m.fpwr(STATION, 0x0610, struct.pack("<IHBBHBBB3x", 96, 36, 0, 7, 0x4800, 0, 1, 1))

    @property
    def block(self) -> MfcioBlock:
        fw = self.seg.firmware[0]
        assert isinstance(fw, MfcioBlock)
        return fw

    def state(self, st: int) -> None:
        self.m.fpwr(STATION, 0x0120, struct.pack("<H", st))
        assert self.m.u16(STATION, 0x0130) == st

    def cycle(self, n: int = 1, **values: int) -> dict[str, int]:
        """n process-data cycles of 1 ms with the outputs ``values`` (others as before)."""
        self.values.update(values)
        self.out = mb0(**self.values)
        for _ in range(n):
            self.clock.advance(CYCLE_NS)
            r = self.m.lrw(0, self.out + bytes(36))
            assert r.wkc == 3
            self.inputs = mb1(r.data[96:])
        return self.inputs


def test_sii_loads_the_configuration_into_the_parameter_ram() -> None:
    b = Bench()
    assert b.m.fprd(STATION, 0x0580, 44).data == b"\x10" * 44
    assert b.m.fprd(STATION, 0x0141, 1).data == b"\x0f"  # device emulation, DC units


def test_move_of_2000_steps_reads_back_2500_counts_and_none_after_safeop() -> None:
    b = Bench()
    b.state(4)
    b.cycle(3, **MOVE)  # SAFEOP: outputs not taken
    assert b.inputs["SD_SC"] == 0
    assert b.block.sd.sr == 0
    b.state(8)
    b.cycle(1)
    assert b.block.sd.sr == sr_for(10_000)
    b.cycle(250)  # 2000 steps at 10 kHz take 200 ms
    assert b.inputs["SD_SC"] == 2000
    assert b.inputs["ENC_X"] == 2500
    assert b.block.shaft is not None and b.block.shaft.microsteps == 2000
    assert b.inputs["ENC_STATUS"] == 1  # ENC_MODE 0x18: N active low, a level event
    b.state(4)
    b.cycle(2, SD_ST=3000, SD_CFG=0)
    b.cycle(200, SD_CFG=1)
    assert b.inputs["SD_SC"] == 2000  # SAFEOP still refreshes the inputs ...
    assert b.inputs["ENC_X"] == 2500
    assert b.block.sd.st == 2000  # ... but takes no outputs: no new move
    b.state(8)
    b.cycle(400)
    assert b.inputs["SD_SC"] == 5000  # in OP the waiting move runs
    assert s32(b.inputs["ENC_X"]) == 6250


def test_inputs_are_not_refreshed_below_safeop() -> None:
    b = Bench()
    b.block.set_gpio_input(0, 1, b.clock.now_ns())
    b.cycle(2)
    assert b.inputs["GPI_IN_VAL"] == 0
    b.state(4)
    b.cycle(2)
    assert b.inputs["GPI_IN_VAL"] == 0b010001  # pin 4 wired high, pin 0 driven now


def test_outputs_are_high_impedance_unless_op_or_overridden() -> None:
    b = Bench()
    b.state(4)
    b.cycle(1, GPIO_CONFIG=0x0F, GPO_OUT_VAL=0x05)
    pins = b.block.pins(b.clock.now_ns())
    assert [pins[f"GPO{i}"] for i in range(4)] == [None, None, None, None]
    b.state(8)
    b.cycle(1)
    pins = b.block.pins(b.clock.now_ns())
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 1, 0]
    assert pins["PWM_HS0"] == 0 and pins["SD_STP"] == 0
    b.state(4)
    b.cycle(1)
    assert b.block.pins(b.clock.now_ns())["GPO0"] is None
    # AL_STATE_OVERRIDE bit 3 (GPIO) through the MFC CTRL SPI: driven again in SAFEOP
    b.block.mfc_write(0x2C0, b"\x08", b.clock.now_ns())
    pins = b.block.pins(b.clock.now_ns())
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 1, 0]
    assert pins["PWM_HS0"] is None  # the PWM block is not overridden


def test_mfcio_watchdog_forces_safe_outputs_when_frames_stop() -> None:
    """WD_TIME 25000 clocks (1 ms) retriggered by the start of frame: while the master
    cycles every 0.5 ms nothing happens; frames stop: GPO0..3 take WD_OUT_POL."""
    b = Bench()
    b.state(8)
    mask_pol = (0x0F << 32) | 0x0A  # GPO0-3 affected; safe levels 0,1,0,1
    b.cycle(1, GPIO_CONFIG=0x0F, GPO_OUT_VAL=0x05, WD_CFG=0x08)
    b.cycle(1, WD_OUT_MASK_POL=mask_pol, WD_OE_POL=0x0F, WD_TIME=25_000)
    for _ in range(10):
        b.clock.advance(500_000)
        b.m.lrw(0, b.out + bytes(36))
    assert not b.block.wd.active
    now = b.clock.now_ns()
    pins = b.block.pins(now + 999_960)
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 1, 0]
    pins = b.block.pins(now + 1_000_000)  # 25000 clocks after the last frame
    assert [pins[f"GPO{i}"] for i in range(4)] == [0, 1, 0, 1]
    assert b.block.wd.active
    b.cycle(1, IRQ_CFG=0x0008)  # the next frame ends the (non-persistent) action
    assert not b.block.wd.active
    b.cycle(1)  # the inputs of a cycle are those the block wrote after the one before
    assert b.inputs["WD_MAX"] == 25_000


def test_nes_brings_pwm_and_gpio_to_their_safe_state_and_freezes_steps() -> None:
    b = Bench()
    b.state(8)
    b.cycle(
        1,
        GPIO_CONFIG=0xFF,
        GPO_OUT_VAL=0x3C0F,
        PWM_MAXCNT=3999,
        PWM_ALIGNMENT=0b10,
        PWM_CHOPMODE=0x0777,
        PWM_POLARITIES=0x02,
        PWM_VALUE_0=2000,
        SD_SR=sr_for(10_000),
        SD_CFG=0x03,
        IRQ_CFG=0x8000,
    )
    b.cycle(10)
    assert b.block.emergency is False
    b.block.set_nes(0, b.clock.now_ns())
    sc = b.block.sd.sc
    b.cycle(10)
    pins = b.block.pins(b.clock.now_ns())
    assert [pins[f"GPO{i}"] for i in range(8)] == [0, 0, 1, 1, 1, 1, 0, 0]  # 0x3C
    assert [pins[f"PWM_HS{i}"] for i in range(3)] == [1, 1, 1]  # off = 1 (POL bit 1)
    assert [pins[f"PWM_LS{i}"] for i in range(3)] == [0, 0, 0]
    assert b.block.sd.sc == sc  # frozen
    assert b.inputs["IRQ_FLAGS"] & 0x8000
    b.block.set_nes(1, b.clock.now_ns())
    b.cycle(5)
    assert b.block.emergency  # latched until IRQ_CFG[15] is written 0 and then 1
    b.cycle(1, IRQ_CFG=0)
    b.cycle(1, IRQ_CFG=0x8000)
    assert not b.block.emergency
    b.cycle(10)
    assert b.block.sd.sc > sc


def test_process_data_watchdog_still_works() -> None:
    """SM2 triggers the ESC's process-data watchdog (0x0400/0x0420): 100 ms without an
    output write and 0x0440 reads expired, 0x0442 counts."""
    b = Bench()
    b.state(4)
    b.state(8)
    b.cycle(5)
    assert b.m.fprd(STATION, 0x0440, 1).data[0] & 1 == 1
    b.clock.advance(100_000_000)
    b.seg.service()
    assert b.m.fprd(STATION, 0x0440, 1).data[0] & 1 == 0
    assert b.m.fprd(STATION, 0x0442, 1).data[0] == 1
    b.cycle(1)
    assert b.m.fprd(STATION, 0x0440, 1).data[0] & 1 == 1


def test_pwm_duty_and_spi_through_process_data() -> None:
    b = Bench()
    b.state(8)
    b.cycle(1, PWM_MAXCNT=3999, PWM_ALIGNMENT=0b11, PWM_CHOPMODE=0x0666, PWM_VALUE_1=1000)
    assert b.block.duties() == [0.0, 0.25, 0.0]
    # SPI: CS1 is a loopback: 32 bits at 6.25 MHz come back
    b.cycle(1, SPI_LENGTH=31, SPI_CONF=0x0061)
    b.cycle(1, SPI_TX_DATA=0xCAFEF00D)  # taken: the transfer starts
    assert b.block.spi.busy_until is not None
    b.cycle(2)  # done by the next run, read by the master a cycle later
    assert b.inputs["SPI_RX_DATA"] == 0xCAFEF00D
    assert b.inputs["SPI_STATUS"] == 1
