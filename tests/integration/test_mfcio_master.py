"""A real master (pysoem) drives the TMC8460 MFCIO block through process data, over veth:
config/tmc8460-mfcio.yaml (MB0 on SM2, MB1 on SM3) and the datasheet's two §6.5 examples
with their ESI. Ref: TMC8460 §6; §5.53.
"""

from __future__ import annotations

import struct
import time
from pathlib import Path
from typing import Any

import pysoem
import pytest

from ecatsim.ctl.server import request
from ecatsim.mfcio.stepdir import sr_for
from tests.integration.test_esc_master import RX_TIMEOUT_US, to_op
from tests.support.mfcio import mb0, mb1, s32

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "tmc8460-mfcio.yaml"
MOVE = {
    "ENC_MODE": 0x18,
    "ENC_CONST": 0x00010000,
    "SD_SR": sr_for(10_000),
    "SD_ST": 2000,
    "SD_CFG": 0x01,
}


class Pd:
    """Process data every millisecond, outputs packed by register name."""

    def __init__(self, master: Any, pack: Any = mb0, unpack: Any = mb1) -> None:
        self.m = master
        self.s = master.slaves[0]
        self.values: dict[str, int] = {}
        self.inputs: dict[str, int] = {}
        self.pack = pack
        self.unpack = unpack
        self.t_next = time.perf_counter()

    def run(self, n: int = 1, **values: int) -> dict[str, int]:
        self.values.update(values)
        self.s.output = self.pack(**self.values)
        for _ in range(n):
            self.m.send_processdata()
            assert self.m.receive_processdata(RX_TIMEOUT_US) == self.m.expected_wkc
            self.inputs = self.unpack(bytes(self.s.input))
            self.t_next += 0.001
            d = self.t_next - time.perf_counter()
            if d > 0:
                time.sleep(d)
        return self.inputs

    def until(self, cond: Any, limit: int = 2000) -> dict[str, int]:
        for _ in range(limit):
            if cond(self.run()):
                return self.inputs
        pytest.fail(f"condition not met within {limit} cycles: {self.inputs}")

    def state(self, st: int) -> None:
        self.m.state = st
        self.m.write_state()
        for _ in range(200):
            self.run()
            if self.m.state_check(st, 5000) == st:
                return
        pytest.fail(f"no state {st}")


def start(daemon_factory: Any, master_factory: Any, tmp: Path, config: Path) -> tuple[Any, Path]:
    sock = tmp / "ctl.sock"
    daemon_factory("--config", str(config), "--ctl", str(sock))
    m = master_factory()
    assert m.config_init() == 1
    to_op(m)
    return m, sock


def ctl(sock: Path, op: str, *args: str) -> dict[str, Any]:
    reply = request(sock, {"cmd": "mfcio", "slave": 0, "op": op, "args": list(args)})
    assert reply["ok"], reply
    return reply


def test_2000_steps_read_back_2500_counts_and_no_step_after_safeop(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    m, sock = start(daemon_factory, master_factory, tmp_path, CONFIG)
    s = m.slaves[0]
    assert (s.man, s.id, s.name) == (0x286, 8460, "TMC8460 MFCIO")
    assert m.expected_wkc == 3
    assert len(s.output) == 96 and len(s.input) == 36
    assert s._fprd(0x0580, 44) == b"\x10" * 44  # category 1 loaded
    pd = Pd(m)
    pd.run(5, **MOVE)
    # 2000 steps at 10 kHz: 200 ms; then nothing moves any more
    pd.until(lambda i: i["SD_SC"] == 2000, 600)
    pd.run(50)
    assert pd.inputs["SD_SC"] == 2000
    assert pd.inputs["ENC_X"] == 2500
    st = ctl(sock, "status")
    assert (st["microsteps"], st["sd_sc"], st["enc_x"]) == (2000, 2000, 2500)
    pd.state(pysoem.SAFEOP_STATE)
    pd.run(5, SD_CFG=0, SD_ST=3000)
    pd.run(300, SD_CFG=0x01)  # a new move while in SAFEOP
    assert pd.inputs["SD_SC"] == 2000  # inputs still refreshed in SAFEOP, no step made
    assert pd.inputs["ENC_X"] == 2500
    assert ctl(sock, "status")["microsteps"] == 2000
    assert ctl(sock, "pins")["pins"]["SD_STP"] is None  # not driven outside OP


def test_each_unit_through_process_data(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    m, sock = start(daemon_factory, master_factory, tmp_path, CONFIG)
    pd = Pd(m)
    # step/dir + IRQ: a move of 3200 steps (one turn) raises "target reached" (bit 1);
    # the encoder latches at the index pulse (pos_edge, ignore A/B, N active high)
    pd.run(2, IRQ_CFG=0x0003, ENC_MODE=0x005C, ENC_CONST=0x00010000)
    pd.run(1, SD_SR=sr_for(40_000), SD_ST=3200, SD_CFG=0x01)
    flags = 0
    for _ in range(400):
        flags |= pd.run()["IRQ_FLAGS"]
        if pd.inputs["SD_SC"] == 3200 and flags & 0x3 == 0x3:
            break
    assert pd.inputs["SD_SC"] == 3200
    assert flags & 0x3 == 0x3  # N event and target reached, each seen in one image
    assert (pd.inputs["ENC_X"], pd.inputs["ENC_LATCH"], pd.inputs["ENC_STATUS"]) == (4000, 4000, 1)
    # SPI: CS1 is a loopback, CS0 a register file answering what was written
    pd.run(2, SPI_LENGTH=39, SPI_CONF=0x0061)
    pd.run(1, SPI_TX_DATA=0x12_3456_789A)
    assert pd.until(lambda i: i["SPI_RX_DATA"] == 0x12_3456_789A)["SPI_STATUS"] == 1
    pd.run(2, SPI_CONF=0x0060, SPI_TX_DATA=(0x80 | 0x10) << 32 | 0x00071703)
    pd.run(2, SPI_TX_DATA=0x10 << 32)
    pd.run(2, SPI_TX_DATA=0x00 << 32)
    assert pd.until(lambda i: i["SPI_RX_DATA"] & 0xFFFFFFFF == 0x00071703)
    # GPIO: outputs on 0-3, input 6 driven from outside through ctl
    pd.run(2, GPIO_CONFIG=0x0F, GPO_OUT_VAL=0x0009)
    ctl(sock, "set", "gpio6", "1")
    inp = pd.until(lambda i: i["GPI_IN_VAL"] & 0x40)["GPI_IN_VAL"]
    assert inp == 0b0101_1001  # pins 0, 3 driven, 4 and 6 from outside
    pins = ctl(sock, "pins")["pins"]
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 0, 1]
    # PWM: 25 kHz, channel 0 at 30 %, complementary, 200 ns brake-before-make
    pd.run(
        2,
        PWM_MAXCNT=3999,
        PWM_ALIGNMENT=0b11,
        PWM_CHOPMODE=0x0007,
        PWM_VALUE_0=1200,
        PWM_BBM_H=20,
        PWM_BBM_L=20,
    )
    assert ctl(sock, "status")["pwm_duty"] == [0.3, 0.0, 0.0]
    # watchdog unit: WD_MAX measures the longest gap between starts of frame
    pd.run(2, WD_CFG=0x08, WD_TIME=25_000_000)
    time.sleep(0.05)
    assert pd.until(lambda i: i["WD_MAX"] > 25 * 40_000)["WD_MAX"] < 25_000_000


def test_mfcio_watchdog_and_nes_force_the_safe_outputs(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    m, sock = start(daemon_factory, master_factory, tmp_path, CONFIG)
    s = m.slaves[0]
    pd = Pd(m)
    mask_pol = (0x0F << 32) | 0x06 | (1 << 52) | (1 << 51)  # GPO0-3 -> 0110, STP/DIR -> 0
    pd.run(2, GPIO_CONFIG=0x0F, GPO_OUT_VAL=0x0A09, WD_CFG=0x08)
    pd.run(2, WD_OUT_MASK_POL=mask_pol, WD_OE_POL=0x0F | 3 << 19, WD_TIME=250_000)
    pins = ctl(sock, "pins")["pins"]
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 0, 1]
    time.sleep(0.05)  # frames stop for 50 ms > WD_TIME (10 ms)
    st = ctl(sock, "status")
    assert st["wd_active"] is True
    pins = ctl(sock, "pins")["pins"]
    assert [pins[f"GPO{i}"] for i in range(4)] == [0, 1, 1, 0]
    assert (pins["SD_STP"], pins["SD_DIR"]) == (0, 0)
    assert s._fprd(0x0440, 1)[0] & 1 == 1  # the process-data watchdog (100 ms) still runs
    time.sleep(0.1)
    assert s._fprd(0x0440, 1)[0] & 1 == 0  # ... and expires after 100 ms without outputs
    assert s._fprd(0x0442, 1)[0] == 1
    pd.t_next = time.perf_counter()
    pd.run(5)  # frames again: the action ends (not persistent)
    assert ctl(sock, "status")["wd_active"] is False
    assert s._fprd(0x0440, 1)[0] & 1 == 1
    # nES: enabled by IRQ_CFG[15]; low -> GPIO safe state (GPO_OUT_VAL[15:8]) latched
    pd.run(2, WD_TIME=0, IRQ_CFG=0x8000)
    ctl(sock, "set", "nes", "0")
    assert pd.until(lambda i: i["IRQ_FLAGS"] & 0x8000)
    pins = ctl(sock, "pins")["pins"]
    assert [pins[f"GPO{i}"] for i in range(4)] == [0, 1, 0, 1]  # 0x0A
    ctl(sock, "set", "nes", "1")
    pd.run(5)
    assert ctl(sock, "status")["emergency"] is True  # latched
    pd.run(2, IRQ_CFG=0)
    pd.run(2, IRQ_CFG=0x8000)
    assert ctl(sock, "status")["emergency"] is False
    pins = ctl(sock, "pins")["pins"]
    assert [pins[f"GPO{i}"] for i in range(4)] == [1, 0, 0, 1]


def _example1_out(**v: int) -> bytes:
    return struct.pack("<HHII", v.get("ENC_MODE", 0), 0, v.get("ENC_X", 0), v.get("ENC_CONST", 0))


def _example1_in(data: bytes) -> dict[str, int]:
    x, latch = struct.unpack("<II", data)
    return {"ENC_X": x, "ENC_LATCH": latch}


def _example2_out(**v: int) -> bytes:
    return struct.pack(
        "<iIHHB",
        v.get("SD_SR", 0),
        v.get("SD_ST", 0),
        v.get("SD_SL", 0),
        v.get("SD_DLY", 0),
        v.get("SD_CFG", 0),
    )


def _example2_in(data: bytes) -> dict[str, int]:
    return {"SD_SC": struct.unpack("<i", data)[0]}


def test_example_1_encoder_with_its_printed_esi(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    """§6.5.1: SM0 0x4000/12 out, SM1 0x4804/8 in; step 5's ENC_MODE 0x18, ENC_CONST 1.0."""
    m, sock = start(daemon_factory, master_factory, tmp_path, ROOT / "config/tmc8460-example1.yaml")
    s = m.slaves[0]
    assert (len(s.output), len(s.input)) == (12, 8)
    assert s._fprd(0x0580, 6) == bytes.fromhex("1E0000101E10")
    pd = Pd(m, _example1_out, _example1_in)
    pd.run(3, ENC_MODE=0x18, ENC_CONST=0x00010000)
    ctl(sock, "set", "encoder", "1000")
    assert pd.until(lambda i: i["ENC_X"] == 1000)
    ctl(sock, "set", "encoder", "-3")
    assert s32(pd.until(lambda i: s32(i["ENC_X"]) == -3)["ENC_X"]) == -3
    assert s32(pd.inputs["ENC_LATCH"]) == -3  # N active low (pol_N = 0): a level event


def test_example_2_step_dir_with_its_esi(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    """§6.5.2: S/D over EtherCAT (SM0 0x4018/13, SM1 0x4818/4), PWM through the MFC CTRL
    SPI (ecatsim ctl as the microcontroller)."""
    m, sock = start(daemon_factory, master_factory, tmp_path, ROOT / "config/tmc8460-example2.yaml")
    s = m.slaves[0]
    assert (len(s.output), len(s.input)) == (13, 4)
    pd = Pd(m, _example2_out, _example2_in)
    pd.run(3, SD_SR=-sr_for(20_000), SD_ST=500, SD_CFG=0x01)
    assert pd.until(lambda i: i["SD_SC"] == -500)
    assert ctl(sock, "status")["microsteps"] == -500
    for reg, v in (("PWM_MAXCNT", 999), ("PWM_ALIGNMENT", 2), ("PWM_CHOPMODE", 6)):
        assert ctl(sock, "write", reg, str(v))["value"] == v
    ctl(sock, "write", "PWM_VALUE_0", "250")  # taken at the next PWM cycle start
    pd.run(2)
    assert ctl(sock, "status")["pwm_duty"] == [0.25, 0.0, 0.0]
    # SD_SR has ECAT access: the MFC CTRL SPI cannot write it
    assert ctl(sock, "write", "SD_SR", "5")["value"] == -sr_for(20_000) & 0xFFFFFFFF


def test_demo_mfcio_beside_the_drive(
    daemon_factory: Any, master_factory: Any, tmp_path: Path, capsys: Any
) -> None:
    """tools/demo_mfcio.py against config/tmc8460-beside-tmc8670.yaml: a TMC8670 and a
    TMC8460 MFCIO slave in one segment; the demo's own checks decide its exit code."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("demo_mfcio", ROOT / "tools" / "demo_mfcio.py")
    assert spec is not None and spec.loader is not None
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    trace = tmp_path / "trace.csv"
    daemon_factory(
        "--config", str(ROOT / "config/tmc8460-beside-tmc8670.yaml"), "--trace", str(trace)
    )
    assert demo.run(master_factory()) == 0
    out = capsys.readouterr().out
    assert "slave 0: TMC8670" in out and "slave 1: TMC8460 MFCIO" in out
    assert "SD_SC 2000 -> 2000" in out
