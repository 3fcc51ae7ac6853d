"""The SPI master unit and the SPI devices a segment wires to its four chip selects.

A transfer of n = SPI_LENGTH + 1 bits at t_SCK = (4 + 2 * SPI_TIME) clocks of 25 MHz
takes half a clock cycle from CSN low to the first SCK edge, n SCK cycles and half a cycle
from the last SCK edge to CSN high: (2n + 1) * (2 + SPI_TIME) clocks, after which
SPI_STATUS.0 (ready) is set again and SPI_RX_DATA holds the received bits.

Ref: TMC8460 §6.7 Tables 140-142, §6.7.3-§6.7.9; decisions M12-M14.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

# SPI_CONF bits. Ref: TMC8460 §6.7.2 Table 141.
CONF_SINGLE_SHOT = 0x8000
CONF_TRIGGER_SHIFT = 8
CONF_TRIGGER_MASK = 0x0700
CONF_CPOL = 0x0040
CONF_CPHA = 0x0020
CONF_LSB_FIRST = 0x0010
CONF_KEEP_CS = 0x0008
CONF_SLAVE_MASK = 0x0003

#: trigger configurations SPI_CONF bits 10..8 (Table 141)
TRIG_TX_WRITE = 0
TRIG_PWM_START = 1
TRIG_PWM_CENTER = 2
TRIG_PWM_A = 3
TRIG_PWM_B = 4
TRIG_PWM_AB = 5
TRIG_SINGLE = 7


def sck_clocks(spi_time: int) -> int:
    """t_SCK in 25 MHz clocks: 4 + 2 * SPI_TIME. Ref: TMC8460 §6.7.8."""
    return 4 + 2 * (spi_time & 0xFF)


def transfer_clocks(nbits: int, spi_time: int) -> int:
    """CSN low to CSN high in 25 MHz clocks: t_SCK/2 before the first SCK edge, the 2n - 1
    half cycles between the first and the last edge, t_SCK/2 after it: (2n + 1) * t_SCK/2.
    Ref: TMC8460 §6.7.8."""
    return (2 * nbits + 1) * sck_clocks(spi_time) // 2


class SpiDevice(Protocol):
    """An SPI slave on one chip select, bit by bit in wire order."""

    def select(self) -> None:
        """CSN went low."""

    def exchange(self, mosi: list[int]) -> list[int]:
        """Clock ``mosi`` bits in (wire order) and return the MISO bits."""

    def deselect(self) -> None:
        """CSN went high: the datagram ends."""


class Loopback:
    """MISO wired to MOSI: every bit comes back as sent."""

    def select(self) -> None:
        pass

    def exchange(self, mosi: list[int]) -> list[int]:
        return list(mosi)

    def deselect(self) -> None:
        pass


class NoDevice:
    """Nothing on this chip select: MISO floats low."""

    def select(self) -> None:
        pass

    def exchange(self, mosi: list[int]) -> list[int]:
        return [0] * len(mosi)

    def deselect(self) -> None:
        pass


@dataclass
class RegisterFile:
    """A stepper-driver register file on the usual 40-bit TMC SPI datagram: byte 0 is the
    address (bit 7 set: write), bytes 1-4 the data, MSB first; the reply to a datagram
    carries a status byte and the data of the register the previous datagram addressed,
    so a read returns its answer in the next datagram (the Trinamic drivers' pipelined
    read). Datagrams of another length are shifted through and ignored. Decision M14."""

    status: int = 0x00
    regs: dict[int, int] | None = None
    count: int = 0  # datagrams taken

    def __post_init__(self) -> None:
        if self.regs is None:
            self.regs = {}
        self._reply = [0] * 40
        self._bits: list[int] = []

    def select(self) -> None:
        self._bits = []

    def exchange(self, mosi: list[int]) -> list[int]:
        start = len(self._bits)
        self._bits.extend(mosi)
        return [self._reply[i] if i < 40 else 0 for i in range(start, start + len(mosi))]

    def deselect(self) -> None:
        bits = self._bits
        self._bits = []
        if len(bits) != 40:
            return
        v = 0
        for b in bits:
            v = (v << 1) | b
        addr = (v >> 32) & 0x7F
        data = v & 0xFFFFFFFF
        assert self.regs is not None
        if v >> 39:
            self.regs[addr] = data
        self.count += 1
        out = (self.status << 32) | self.regs.get(addr, 0)
        self._reply = [(out >> (39 - i)) & 1 for i in range(40)]


DEVICE_KINDS = ("loopback", "register_file", "none")


def make_device(kind: str) -> SpiDevice:
    if kind == "loopback":
        return Loopback()
    if kind == "register_file":
        return RegisterFile()
    return NoDevice()


class SpiMaster:
    """The SPI master unit on 25 MHz clocks: one transfer at a time."""

    def __init__(self, devices: list[SpiDevice] | None = None) -> None:
        self.devices: list[SpiDevice] = devices or [NoDevice() for _ in range(4)]
        self.tx = 0
        self.conf = 0
        self.length = 0
        self.time = 0
        self.rx = 0
        self.busy_until: int | None = None  # end clock of the transfer in progress
        self._pending_rx = 0
        self.armed = False  # PWM-linked trigger: a written TX waits for its mark
        self.cs_low: int | None = None  # the chip select held low (keep CS), if any
        self.transfers = 0
        self.ignored = 0  # starts while busy (SPI_STATUS.0 = 0): ignored (§6.7.6)
        self.new_data = 0  # completed transfers since the IRQ unit last looked
        self.last_start: int | None = None

    @property
    def nbits(self) -> int:
        return (self.length & 0x3F) + 1

    def ready(self, tick: int) -> bool:
        self.advance(tick)
        return self.busy_until is None

    def status(self, tick: int) -> int:
        """SPI_STATUS: bit 0 ready. Ref: TMC8460 §6.7.6."""
        return 1 if self.ready(tick) else 0

    def trigger_mode(self) -> int:
        return (self.conf & CONF_TRIGGER_MASK) >> CONF_TRIGGER_SHIFT

    def write(self, name: str, value: int, tick: int) -> None:
        """Take a register; a value change is a write (decision M2). Writing SPI_TX_DATA
        starts a transfer in trigger mode 0, arms one for the next PWM mark in modes 1-5;
        SPI_CONF bit 15 starts one in mode 7. Ref: TMC8460 §6.7.4, §6.7.5."""
        self.advance(tick)
        if name == "SPI_TX_DATA":
            value &= (1 << 64) - 1
            if value == self.tx:
                return
            self.tx = value
            mode = self.trigger_mode()
            if mode == TRIG_TX_WRITE:
                self.start(tick)
            elif 1 <= mode <= 5:
                self.armed = True
        elif name == "SPI_CONF":
            value &= 0x877B
            if value == self.conf:
                return
            old, self.conf = self.conf, value
            if (
                value & CONF_SINGLE_SHOT
                and not old & CONF_SINGLE_SHOT
                and self.trigger_mode() == TRIG_SINGLE
            ):
                self.start(tick)
        elif name == "SPI_LENGTH":
            self.length = value & 0x3F
        elif name == "SPI_TIME":
            self.time = value & 0xFF
        else:
            raise KeyError(name)

    def fire(self, tick: int) -> None:
        """The PWM mark SPI_CONF 10..8 selects (1-5) came at ``tick``: the transfer a
        write of SPI_TX_DATA armed starts (once per write, decision M13)."""
        if self.armed:
            self.armed = False
            self.start(tick)

    def start(self, tick: int) -> None:
        """Start a transfer at ``tick``: the bits are exchanged with the device now, the
        result shows when the transfer ends. Ref: TMC8460 §6.7.6 (busy: ignored)."""
        self.advance(tick)
        if self.busy_until is not None:
            self.ignored += 1
            return
        n = self.nbits
        cs = self.conf & CONF_SLAVE_MASK
        dev = self.devices[cs]
        if self.cs_low is not None and self.cs_low != cs:
            self.devices[self.cs_low].deselect()
            self.cs_low = None
        if self.cs_low is None:
            dev.select()
        lsb = bool(self.conf & CONF_LSB_FIRST)
        order = range(n) if lsb else range(n - 1, -1, -1)
        mosi = [(self.tx >> i) & 1 for i in order]
        miso = dev.exchange(mosi)
        rx = 0
        for i, b in zip(order, miso, strict=True):
            rx |= (b & 1) << i
        if self.conf & CONF_KEEP_CS:
            self.cs_low = cs
        else:
            dev.deselect()
            self.cs_low = None
        self._pending_rx = rx
        self.busy_until = tick + transfer_clocks(n, self.time)
        self.last_start = tick
        self.transfers += 1

    def advance(self, tick: int) -> None:
        """Finish the transfer in progress if it has ended by ``tick``."""
        end = self.busy_until
        if end is not None and tick >= end:
            self.busy_until = None
            self.rx = self._pending_rx
            self.new_data += 1

    def cs_levels(self, tick: int) -> list[int]:
        """CSN0..3 pin levels (low active)."""
        self.advance(tick)
        levels = [1, 1, 1, 1]
        if self.busy_until is not None:
            levels[self.conf & CONF_SLAVE_MASK] = 0
        if self.cs_low is not None:
            levels[self.cs_low] = 0
        return levels
