"""The MFCIO configuration in the tools: the SII category 1 built from a description or an
ESI, decoded by ``eeprom show`` and ``esi export``, reloaded by the EEPROM reload command;
the shadow triggers; the ``--trace`` rows. Ref: TMC8460 §6.3-§6.5, §5.45 Table 62."""

from __future__ import annotations

import csv
import struct
from pathlib import Path

from click.testing import CliRunner

from ecatsim.cli import cli
from ecatsim.device.description import default_description
from ecatsim.device.esi import export_esi, read_esi
from ecatsim.mfcio import trace as mfcio_trace
from ecatsim.sii.image import build_image, format_image, parse_image
from tests.unit.mfcio.test_mfcio_block import STATION, Bench

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE1 = ROOT / "config" / "tmc8460-example1.xml"


def test_esi_export_round_trips_to_the_same_sii_image(tmp_path: Path) -> None:
    desc = default_description("tmc8460.yaml")
    xml = tmp_path / "tmc8460.xml"
    xml.write_bytes(export_esi(desc, None))
    again = read_esi(xml)
    assert again.mfcio_config == b"\x10" * 44
    assert build_image(again, serial=1) == build_image(desc)  # an ESI has no serial
    text = xml.read_text()
    assert "<CatNo>1</CatNo>" in text
    assert "<!-- 43 WD_MAX R 0x10 ECAT MB1 0x4820, trigger 0 (always) -->" in " ".join(text.split())


def test_example_1_esi_builds_category_1_first() -> None:
    desc = read_esi(EXAMPLE1)
    img = parse_image(build_image(desc))
    typ, word, body = img.categories[0]
    assert (typ, word, body) == (1, 0x40, bytes.fromhex("1E0000101E10"))
    assert img.words[0] == 0x0300  # ConfigData 00 03: 0x0141 = 0x03, device emulation
    assert [s[:3] for s in img.sms] == [(0x4000, 12, 0x04), (0x4804, 8, 0x00)]
    text = format_image(img)
    assert "category MFCIO (type 1) at word 0x0040, 3 words" in text
    assert "   0 ENC_MODE          W 0x1E ECAT MB0 0x4000, trigger 14" in text
    assert "   5 ENC_LATCH         R 0x10 ECAT MB1 0x4808, trigger 0 (always)" in text


def test_eeprom_build_and_show_decode_the_registers(tmp_path: Path) -> None:
    out = tmp_path / "ex1.bin"
    runner = CliRunner()
    r = runner.invoke(cli, ["eeprom", "build", str(EXAMPLE1), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(cli, ["eeprom", "show", str(out)])
    assert r.exit_code == 0, r.output
    assert "   4 ENC_CONST         W 0x1E ECAT MB0 0x4008, trigger 14" in r.output
    assert "  43 WD_MAX            R 0x00 unused (0x00), trigger 0 (always)" in r.output
    r = runner.invoke(cli, ["esi", "export", "--device", "tmc8460", "-o", str(tmp_path / "e.xml")])
    assert r.exit_code == 0, r.output
    assert read_esi(tmp_path / "e.xml").mfcio_config == b"\x10" * 44


def test_eeprom_reload_restores_the_parameter_ram() -> None:
    """The master may rewrite 0x0580 at run time; an EEPROM reload (command 100) loads the
    category again. Ref: TMC8460 §6.2, §5.45 Table 62."""
    b = Bench()
    b.m.fpwr(STATION, 0x0580, b"\x00\x1e")
    assert b.m.fprd(STATION, 0x0580, 2).data == b"\x00\x1e"
    b.m.fpwr(STATION, 0x0502, struct.pack("<H", 0x0400))
    assert b.m.fprd(STATION, 0x0580, 44).data == b"\x10" * 44


def test_registers_without_ecat_access_take_mfc_ctrl_spi_writes_at_deselect() -> None:
    b = Bench()
    b.m.fpwr(STATION, 0x0580 + 18, b"\x0a")  # PWM_MAXCNT: MFC CTRL SPI, deselect
    b.state(4)
    b.state(8)
    b.cycle(2, PWM_MAXCNT=100)  # no ECAT access: ignored
    assert b.block.pwm.period == 1
    now = b.clock.now_ns()
    b.block.mfc_write(18 << 4, struct.pack("<H", 999), now)
    assert b.block.pwm.period == 1000
    assert b.block.mfc_read(18 << 4, 2, now) == struct.pack("<H", 999)
    b.block.mfc_write(12 << 4, b"\x01", now)  # SD_SR has ECAT access: not writable here
    assert b.block.shadow[12] == 0


def test_pwm_cycle_trigger_waits_for_the_cycle_start() -> None:
    b = Bench()
    b.state(4)
    b.state(8)
    b.cycle(2, PWM_MAXCNT=3999, PWM_ALIGNMENT=2, PWM_CHOPMODE=6)
    b.m.fpwr(STATION, 0x0580 + 22, b"\x1d")  # PWM_VALUE_0: ECAT, trigger 13
    b.cycle(1, PWM_VALUE_0=2000)
    blk = b.block
    assert blk.pwm.r["PWM_VALUE_0"] == 0
    (due, num, value) = blk.pending[0]
    assert (num, value) == (22, 2000)
    assert due % 10 == 0 and blk.pwm.counter(due // 10) == 0  # a cycle start
    blk.advance(due - 10)
    assert blk.pwm.r["PWM_VALUE_0"] == 0
    blk.advance(due)
    assert blk.pwm.r["PWM_VALUE_0"] == 2000


def test_sof_trigger_takes_values_with_the_next_frame_only() -> None:
    b = Bench()
    b.m.fpwr(STATION, 0x0580 + 35, b"\x15")  # GPIO_CONFIG: ECAT, start of frame
    b.state(4)
    b.state(8)
    b.cycle(1, GPIO_CONFIG=0x0F)
    assert b.block.gpio.config == 0x0F
    b.block.shadow[35] = 0x01
    b.block.service(b.clock.now_ns())  # a run without a new frame: nothing moves
    assert b.block.gpio.config == 0x0F


def test_trace_rows(tmp_path: Path) -> None:
    b = Bench()
    w = mfcio_trace.attach([(0, b.block)], tmp_path / "run.csv")
    assert w is not None and w.path == tmp_path / "run.mfcio.csv"
    b.state(4)
    b.state(8)
    b.cycle(
        30,
        SD_SR=1 << 26,
        SD_CFG=3,
        PWM_MAXCNT=999,
        PWM_ALIGNMENT=2,
        PWM_CHOPMODE=0x0007,
        PWM_VALUE_0=250,
        GPIO_CONFIG=0x03,
        GPO_OUT_VAL=0x01,
    )
    w.close()
    with open(w.path, newline="") as f:
        rows = list(csv.DictReader(f))
    last = rows[-1]
    assert tuple(rows[0]) == mfcio_trace.COLUMNS
    assert last["al_state"] == "8"
    assert int(last["sd_sc"]) == b.block.sd.sc > 0
    assert last["pwm_duty0"] == "0.250000"
    assert last["gpio_pins"] == "ZZ01ZZ01"  # pins 7..0: 4 and 5 wired from outside
    assert rows[0]["pwm_hs0"] == "Z"  # INIT: not driven


def test_ctl_mfcio_answers(tmp_path: Path) -> None:
    """``ecatsim ctl mfcio``: status, pins, inputs, the MFC CTRL SPI; errors as one line."""
    import json

    from ecatsim.ctl.server import ControlSocket
    from ecatsim.faults.engine import FaultEngine

    b = Bench()
    c = ControlSocket(tmp_path / "ctl.sock", b.seg, FaultEngine(b.seg))
    try:

        def ask(**req: object) -> dict[str, object]:
            return c.answer(json.dumps({"cmd": "mfcio", "slave": 0, **req}).encode())

        assert ask(op="status")["sd_sc"] == 0
        assert ask(op="set", args=["gpio2", "1"])["pins"]["GPO2"] == 1  # type: ignore[index]
        assert ask(op="write", args=["AL_STATE_OVERRIDE", "0x0F"]) == {
            "ok": True,
            "register": "AL_STATE_OVERRIDE",
            "value": 15,
        }
        assert ask(op="read", args=["nope"]) == {
            "ok": False,
            "error": "nope: no such MFCIO register (TMC8460 Table 133)",
        }
        assert ask(op="set", args=["gpio9", "1"])["ok"] is False
        reply = c.answer(json.dumps({"cmd": "mfcio", "slave": 5}).encode())
        assert reply == {"ok": False, "error": "no slave 5"}
    finally:
        c.close()


def test_sync0_trigger_takes_values_at_the_pulse() -> None:
    """Trigger 1: a value waits in the shadow register until a SYNC0 pulse (seen by the
    run the pulse starts: SYNC0 is mapped to AL event 0x0220.2 in tmc8460.yaml)."""
    b = Bench()
    b.m.fpwr(STATION, 0x0580 + 35, b"\x11")  # GPIO_CONFIG: ECAT, SYNC0
    b.state(4)
    b.state(8)
    b.cycle(3, GPIO_CONFIG=0x0F)
    assert b.block.gpio.config == 0
    now = struct.unpack("<Q", b.m.fprd(STATION, 0x0910, 8).data)[0]
    b.m.fpwr(STATION, 0x09A0, struct.pack("<I", 1_000_000))
    b.m.fpwr(STATION, 0x0990, struct.pack("<Q", now + 1_500_000))
    b.m.fpwr(STATION, 0x0981, b"\x03")
    b.cycle(1)
    assert b.block.gpio.config == 0  # no pulse yet
    b.cycle(1)
    assert b.block.gpio.config == 0x0F
