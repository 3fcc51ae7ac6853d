"""Golden tests of the MFCIO register map (Table 133, Tables 129-132), the configuration
byte (Tables 135/136), GPIO (§6.10), the IRQ unit (§6.12, §6.13) and the IO watchdog
(§6.11)."""

from __future__ import annotations

from ecatsim.mfcio import regs as R
from ecatsim.mfcio.config import RegConfig, Trigger, category_body, describe, vector
from ecatsim.mfcio.gpio import Gpio
from ecatsim.mfcio.irq import NES, SRC_ENC_N, SRC_SD_TARGET, Irq
from ecatsim.mfcio.watchdog import CFG_IN_EDGE, CFG_PERSISTENT, CFG_SOF, IoWatchdog


def test_table_133_addresses() -> None:
    assert len(R.REGISTERS) == 45
    assert [r.num for r in R.REGISTERS] == list(range(45))
    enc_x = R.reg("ENC_X")
    assert (enc_x.num, enc_x.config_addr, enc_x.eeprom_addr, enc_x.mb) == (
        3,
        0x0583,
        0x0087,
        0x4804,
    )
    wd_max = R.reg("WD_MAX")
    assert (wd_max.config_addr, wd_max.eeprom_addr, wd_max.mb) == (0x05AB, 0x00AF, 0x4820)
    assert R.reg("SPI_TX_DATA").spi_addr(3) == 0x73  # register 7, byte 3 (§3.6)
    assert R.by_spi_addr(0x2C0) == (R.AL_STATE_OVERRIDE, 0)
    assert R.by_spi_addr(0x2C1) is None


def test_memory_blocks_are_dense_apart_from_the_padding() -> None:
    """MB0 0x4000:0x405F and MB1 0x4800:0x4823: every byte is a register or padding."""
    for writable, start, size, padding in (
        (True, R.MB0_START, R.MB0_SIZE, R.MB0_PADDING),
        (False, R.MB1_START, R.MB1_SIZE, R.MB1_PADDING),
    ):
        owner = [""] * size
        for r in R.REGISTERS:
            if r.mb is None or r.writable != writable:
                continue
            for i in range(r.size):
                assert not owner[r.mb - start + i]
                owner[r.mb - start + i] = r.name
            # §5.53: 2-byte registers at even, 4/8-byte registers at 4-byte addresses
            assert r.mb % min(r.size, 4) == 0, r.name
        for addr, n in padding:
            for i in range(n):
                assert not owner[addr - start + i]
                owner[addr - start + i] = "pad"
        assert all(owner), [hex(start + i) for i, o in enumerate(owner) if not o]


def test_configuration_byte() -> None:
    assert RegConfig.of(0x1E) == RegConfig(True, Trigger.ON_CHANGE)
    assert RegConfig.of(0x0D) == RegConfig(False, Trigger.PWM_CYCLE)
    assert RegConfig(True, Trigger.SYNC0).byte == 0x11
    # reserved bits 7..5 read 0 (Table 74); a short vector is completed with 0x00 (§6.4)
    assert vector(bytes([0xFE, 0x10])) == bytes([0x1E, 0x10]) + bytes(42)


def test_example_1_category_decoded_register_by_register() -> None:
    """§6.5.1: <Data>1E0000101E10</Data>."""
    lines = describe(bytes.fromhex("1E0000101E10"))
    assert len(lines) == 44
    assert lines[0] == (
        "   0 ENC_MODE          W 0x1E ECAT MB0 0x4000, trigger 14 (when data value changes)"
    )
    assert lines[1] == "   1 ENC_STATUS        R 0x00 unused (0x00), trigger 0 (always)"
    assert lines[3] == "   3 ENC_X             R 0x10 ECAT MB1 0x4804, trigger 0 (always)"
    assert category_body(vector(bytes.fromhex("1E0000101E10"))) == bytes.fromhex("1E0000101E10")
    assert category_body(bytes([0x10])) == b"\x10\x00"


def test_gpio_outputs_inputs_and_safe_state() -> None:
    g = Gpio()
    g.write("GPIO_CONFIG", 0x0F)
    g.write("GPO_OUT_VAL", 0xA05)  # values 0x05, safe state 0x0A
    assert g.driven(True, False) == [1, 0, 1, 0, None, None, None, None]
    assert g.driven(True, True) == [0, 1, 0, 1, None, None, None, None]
    assert g.driven(False, False) == [None] * 8  # not OP: high impedance (§6.1)
    assert g.in_val([1, 0, 1, 0, 1, None, 0, 1]) == 0b10010101


def test_irq_flags_of_enabled_sources_clear_on_read() -> None:
    q = Irq()
    q.write("IRQ_CFG", SRC_ENC_N)
    q.raise_(SRC_ENC_N | SRC_SD_TARGET)
    assert q.flags == SRC_ENC_N
    assert q.line == 1
    assert q.read_flags() == SRC_ENC_N
    assert (q.flags, q.line) == (0, 0)


def test_emergency_flag_needs_two_writes_of_bit_15() -> None:
    """§6.13.2: the flag stays after nES returns high; IRQ_CFG[15] = 0 then 1 clears it;
    reading IRQ_FLAGS does not."""
    q = Irq()
    q.write("IRQ_CFG", NES)
    q.emergency()
    assert q.read_flags() == NES
    assert q.flags == NES
    q.write("IRQ_CFG", NES | SRC_ENC_N)  # bit 15 stays 1: no reset
    assert q.flags == NES
    q.write("IRQ_CFG", 0)
    assert q.flags == NES
    q.write("IRQ_CFG", NES)
    assert q.flags == 0


def test_watchdog_expires_at_wd_time_and_measures_wd_max() -> None:
    w = IoWatchdog()
    w.write("WD_CFG", CFG_SOF, 0)
    w.write("WD_OUT_MASK_POL", (1 << 32 | 1 << 52) << 0 | 1, 0)  # GPO0 -> 1, SD_STP -> 0
    w.write("WD_OE_POL", 1 | 1 << 20, 0)
    w.write("WD_TIME", 25_000, 100)  # 1 ms of 25 MHz clocks
    w.event(CFG_SOF, 10_100)
    assert w.max == 10_000  # the counter reached 10000 before the start of frame
    w.advance(35_099)
    assert not w.active
    assert w.max == 24_999
    w.advance(35_100)
    assert w.active and w.expired_at == 35_100 and w.timeouts == 1
    assert w.max == 25_000
    assert w.force(0) == (1, 1)
    assert w.force(20) == (0, 1)
    assert w.force(1) is None
    w.event(CFG_SOF, 40_000)  # not persistent: the next trigger ends the action
    assert not w.active
    assert w.force(0) is None


def test_persistent_timeout_ends_only_with_a_new_wd_time() -> None:
    w = IoWatchdog()
    w.write("WD_CFG", CFG_SOF | CFG_PERSISTENT, 0)
    w.write("WD_TIME", 100, 0)
    w.advance(200)
    w.event(CFG_SOF, 300)
    assert w.active
    w.write("WD_TIME", 100, 400)
    assert not w.active and w.max == 0


def test_watchdog_input_condition_edge() -> None:
    """WD_IN_MASK_POL: GPI0 must reach 1; cfg_in_edge 1 retriggers on the condition
    becoming true, not on it staying true."""
    w = IoWatchdog()
    w.write("WD_CFG", CFG_IN_EDGE, 0)
    w.write("WD_IN_MASK_POL", 1 << 16 | 1, 0)
    w.write("WD_TIME", 1000, 0)
    w.inputs(0, 100)
    w.inputs(1, 500)  # becomes true: retrigger
    w.inputs(1, 900)  # stays true: nothing
    w.advance(1499)
    assert not w.active
    w.advance(1500)
    assert w.active
