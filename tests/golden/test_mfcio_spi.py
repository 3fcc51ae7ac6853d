"""Golden tests of the MFCIO SPI master against TMC8460 §6.7: t_SCK = (4 + 2 * SPI_TIME)
clocks of 25 MHz, t_SCK/2 from CSN to the first and from the last SCK edge to CSN,
SPI_LENGTH + 1 bits, bit order, keep-CS datagrams, ready flag, and the §6.7.9 examples."""

from __future__ import annotations

import pytest

from ecatsim.mfcio.spi import (
    Loopback,
    NoDevice,
    RegisterFile,
    SpiDevice,
    SpiMaster,
    sck_clocks,
    transfer_clocks,
)
from ecatsim.mfcio.timebase import F_CLK_HZ, TICK_NS


class Recorder:
    """A shift-register chain: records every datagram (CSN low to high) bit by bit."""

    def __init__(self) -> None:
        self.frames: list[list[int]] = []
        self._bits: list[int] = []

    def select(self) -> None:
        self._bits = []

    def exchange(self, mosi: list[int]) -> list[int]:
        self._bits.extend(mosi)
        return [1, 0] * (len(mosi) // 2) + [1] * (len(mosi) % 2)

    def deselect(self) -> None:
        self.frames.append(self._bits)


def bits(value: int, n: int) -> list[int]:
    return [(value >> (n - 1 - i)) & 1 for i in range(n)]


def master(dev: SpiDevice) -> SpiMaster:
    return SpiMaster([dev, NoDevice(), NoDevice(), NoDevice()])


@pytest.mark.parametrize(("spi_time", "f_hz"), [(0, 6_250_000), (2, 3_125_000), (11, 961_538)])
def test_sck_frequency(spi_time: int, f_hz: int) -> None:
    """f_SCK = 25 MHz / (4 + 2 * SPI_TIME): §6.7.9 uses 0 -> 6.25 MHz, 2 -> 3.125 MHz."""
    assert F_CLK_HZ // sck_clocks(spi_time) == f_hz


def test_tmc262_example_timing_and_ready() -> None:
    """§6.7.9 TMC262: SPI_TIME 2, 20 bits (SPI_LENGTH 0x13), SPI_CONF 0x0060: CSN low for
    t_SCK/2 + 20 t_SCK + ... = (2 * 20 + 1) * 4 clocks = 164 clocks = 6.56 us."""
    rec = Recorder()
    m = master(rec)
    m.write("SPI_TIME", 0x02, 0)
    m.write("SPI_LENGTH", 0x13, 0)
    m.write("SPI_CONF", 0x0060, 0)
    assert m.status(0) == 1
    m.write("SPI_TX_DATA", 0x00000000000EF010, 100)
    assert transfer_clocks(20, 2) == 164
    assert 164 * TICK_NS == 6560
    assert m.status(263) == 0
    assert m.cs_levels(263) == [0, 1, 1, 1]
    assert m.status(264) == 1
    assert m.cs_levels(264) == [1, 1, 1, 1]
    assert rec.frames == [bits(0xEF010, 20)]  # MSB first
    assert m.rx == 0b10101010101010101010


def test_lsb_first_reverses_both_directions() -> None:
    rec = Recorder()
    m = master(rec)
    m.write("SPI_LENGTH", 7, 0)
    m.write("SPI_CONF", 0x0010, 0)
    m.write("SPI_TX_DATA", 0x01, 0)
    m.advance(100)
    assert rec.frames == [[1, 0, 0, 0, 0, 0, 0, 0]]
    assert m.rx == 0b01010101  # the first received bit is RX bit 0


def test_loopback_returns_the_datagram() -> None:
    m = master(Loopback())
    m.write("SPI_LENGTH", 63, 0)
    m.write("SPI_TX_DATA", 0x0123456789ABCDEF, 0)
    m.advance(transfer_clocks(64, 0))
    assert m.rx == 0x0123456789ABCDEF


def test_start_while_busy_is_ignored() -> None:
    """§6.7.6: a trigger while SPI_STATUS.0 = 0 is ignored."""
    rec = Recorder()
    m = master(rec)
    m.write("SPI_LENGTH", 7, 0)
    m.write("SPI_TX_DATA", 0x11, 0)
    m.write("SPI_TX_DATA", 0x22, 10)
    assert (m.transfers, m.ignored) == (1, 1)
    assert rec.frames == [bits(0x11, 8)]


def test_74xx595_chain_of_80_bits_in_two_40_bit_transfers() -> None:
    """§6.7.9 good example: 0x5555AAAA55 with keep-CS (SPI_CONF 0x0068), then 0x55AAAA55AA
    with CS released (0x0060): one 80-bit datagram 0x5555AAAA5555AAAA55AA. 40 bits are
    SPI_LENGTH 0x27 by §6.7.7 (the example's 0x28 would be 41 bits, decision M12)."""
    rec = Recorder()
    m = master(rec)
    m.write("SPI_TIME", 0, 0)
    m.write("SPI_LENGTH", 0x27, 0)
    m.write("SPI_CONF", 0x0068, 0)
    m.write("SPI_TX_DATA", 0x5555AAAA55, 0)
    t = transfer_clocks(40, 0)
    assert m.cs_levels(t) == [0, 1, 1, 1]  # ready, CS held low
    assert rec.frames == []
    m.write("SPI_CONF", 0x0060, t)
    m.write("SPI_TX_DATA", 0x55AAAA55AA, t)
    assert m.cs_levels(2 * t) == [1, 1, 1, 1]
    assert rec.frames == [bits(0x5555AAAA5555AAAA55AA, 80)]


def test_register_file_answers_reads_of_what_was_written() -> None:
    """A 40-bit datagram writes (address | 0x80); the next datagram's reply carries the
    register the previous datagram addressed."""
    rf = RegisterFile()
    m = master(rf)
    m.write("SPI_LENGTH", 39, 0)
    m.write("SPI_CONF", 0x0060, 0)
    t = transfer_clocks(40, 0)
    m.write("SPI_TX_DATA", (0x80 | 0x6C) << 32 | 0x000100C3, 0)  # write CHOPCONF
    m.write("SPI_TX_DATA", 0x6C << 32, t)  # read CHOPCONF
    m.write("SPI_TX_DATA", 0x00 << 32, 2 * t)  # any: carries the answer
    m.advance(3 * t)
    assert rf.regs == {0x6C: 0x000100C3}
    assert m.rx == 0x000100C3


def test_single_shot_trigger_7() -> None:
    rec = Recorder()
    m = master(rec)
    m.write("SPI_LENGTH", 7, 0)
    m.write("SPI_CONF", 0x0700, 0)
    m.write("SPI_TX_DATA", 0x5A, 0)
    assert m.transfers == 0  # not on the TX write
    m.write("SPI_CONF", 0x8700, 1)
    assert m.transfers == 1
    m.write("SPI_CONF", 0x8701, 100)  # bit 15 still set: not a new start
    assert m.transfers == 1
