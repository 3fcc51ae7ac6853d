"""The PDI SPI datagrams of TMC8460 §3.5.1 byte for byte, its error counter and code
(§5.36, §5.37 Table 51), the PDI watchdog (§5.40) and the AL state owned by the external
firmware (§5.21, §5.32)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from ecatsim.clock import ManualClock
from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.ethercat.segment import Segment
from ecatsim.pdi_spi.external import ExternalFirmware
from ecatsim.pdi_spi.protocol import SpiTiming, transfer
from tests.support.tinymaster import TinyMaster, segment_of


def external(tmp_path: Path) -> tuple[Segment, ManualClock, TinyMaster, ExternalFirmware]:
    seg, clock = segment_of(1, firmware="external", pdi_socket=tmp_path / "pdi.sock")
    fw = seg.firmware[0]
    assert isinstance(fw, ExternalFirmware)
    return seg, clock, TinyMaster(seg, clock), fw


SLOW = SpiTiming()  # 1 MHz SCK: a plain read has its 240 ns


def spi(fw: ExternalFirmware, *mosi: int, timing: SpiTiming = SLOW) -> bytes:
    return transfer(fw, bytes(mosi), timing)


def errors(m: TinyMaster) -> tuple[int, int]:
    r = m.aprd(0, 0x030D, 2).data
    return r[0], r[1]


@pytest.fixture
def chip(tmp_path: Path):  # type: ignore[no-untyped-def]
    seg, clock, m, fw = external(tmp_path)
    yield seg, clock, m, fw
    fw.close()


def test_nop_returns_the_event_registers(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    assert spi(fw, 0x00, 0x00) == b"\x00\x00"
    m.apwr(0, 0x0120, struct.pack("<H", 0x0008))  # the master asks for OP: AL control event
    assert spi(fw, 0x00, 0x00) == bytes([0x01, 0x00])  # §3.5.1 "Command 0" example


def test_read_of_al_control(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    m.apwr(0, 0x0120, struct.pack("<H", 0x0008))
    # §3.5.1 "Command 2": read 0x0120:0x0121, operational state requested
    assert spi(fw, 0x09, 0x02, 0x00, 0xFF) == bytes([0x01, 0x00, 0x08, 0x00])
    # reading AL control from the PDI clears the AL control event (§5.32 Table 46 bit 0)
    assert spi(fw, 0x00, 0x00) == b"\x00\x00"
    assert errors(m) == (0, 0)


def test_read_with_wait_state_3_byte_address(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    m.apwr(0, 0x3400, b"DATA")
    got = spi(fw, 0xA0, 0x06, 0x2C, 0xFF, 0x00, 0x00, 0x00, 0xFF)
    # §3.5.1 "Command 3": 0x00 0x00 0x00 0xXX "DATA"; the undefined byte is 0x00 here
    assert got == bytes([0x00, 0x00, 0x00, 0x00, 0x44, 0x41, 0x54, 0x41])


def test_write_and_padded_write(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    assert spi(fw, 0x10, 0x06, 0x50, 0x4C, 0x48) == bytes(5)  # §3.5.1 "Command 4"
    assert m.aprd(0, 0x4200, 2).data == b"\x4c\x48"
    m.apwr(0, 0x4200, b"\x00\x00")
    # §3.5.1 "Command 6": the third byte repeated with the address extension command
    assert spi(fw, 0x10, 0x06, 0x58, 0x58, 0x58, 0x50, 0x4C, 0x48) == bytes(8)
    assert m.aprd(0, 0x4200, 2).data == b"\x4c\x48"
    assert errors(m) == (0, 0)


def test_address_phase_echoes_0x0222_in_3_byte_mode(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    m.apwr(0, 0x0120, struct.pack("<H", 0x0002))
    got = spi(fw, 0x09, 0x06, 0x0C, 0xFF, 0x00, 0xFF)  # 0x0120 in 3-byte mode, wait state
    assert got == bytes([0x01, 0x00, 0x00, 0x00, 0x02, 0x00])


@pytest.mark.parametrize(
    ("mosi", "code"),
    [
        ((0x00, 0x05), 0x80),  # reserved command 5: CMD[2:1] = 10
        ((0x00, 0x07), 0xC0),  # reserved command 7
        ((0x00, 0x01), 0x00),  # reserved command 1
        ((0x10, 0x06), 0xC0),  # ends inside the 3-byte address phase
        ((0x10,), 0x00),  # ends after one byte
        ((0x09, 0x02, 0x00, 0x00), 0x50),  # read termination missing
        ((0x09, 0x03, 0xFF), 0x50),  # read with wait state, no data at all
        ((0x09, 0x02, 0xFF, 0x00), 0x60),  # access continued after the termination byte
    ],
)
def test_interface_errors_count_with_their_code(chip, mosi, code) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    spi(fw, *mosi)
    assert errors(m) == (1, code)
    spi(fw, *mosi)
    assert errors(m) == (2, code)
    m.apwr(0, 0x030D, b"\x00")  # a master write clears counter and code (§5.36 note)
    assert errors(m) == (0, 0)


def test_a_plain_read_too_fast_for_the_chip_is_a_busy_violation(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    m.apwr(0, 0x3400, b"DATA")
    fast = SpiTiming(sck_hz=30_000_000)
    assert spi(fw, 0xA0, 0x06, 0x28, 0x00, 0x00, 0x00, 0xFF, timing=fast) == bytes(7)
    assert errors(m) == (1, 0x48)
    # with the pause §3.5.1 asks for, or with the wait state byte, the same read works
    paused = SpiTiming(sck_hz=30_000_000, read_pause_ns=240)
    got = spi(fw, 0xA0, 0x06, 0x28, 0x00, 0x00, 0x00, 0xFF, timing=paused)
    assert got[3:] == b"DATA"
    got = spi(fw, 0xA0, 0x06, 0x2C, 0xFF, 0x00, 0x00, 0x00, 0xFF, timing=fast)
    assert got[4:] == b"DATA"
    assert errors(m) == (1, 0x48)


def test_al_status_is_the_firmware_s(chip) -> None:  # type: ignore[no-untyped-def]
    _, _, m, fw = chip
    m.apwr(0, 0x0120, struct.pack("<H", 0x0002))
    assert m.aprd(0, 0x0130, 2).data == b"\x01\x00"  # nobody answered: still INIT
    spi(fw, 0x09, 0x84, 0x02, 0x00)  # write 0x0130 = PREOP
    assert m.aprd(0, 0x0130, 2).data == b"\x02\x00"


def test_the_pdi_watchdog_expires_without_accesses(chip) -> None:  # type: ignore[no-untyped-def]
    seg, clock, m, fw = chip
    assert m.aprd(0, 0x0110, 1).data[0] & 0x02  # reloaded after power-up
    clock.advance(99_000_000)  # 0x0410 = 1000 x 100 us (0x0400 = 2498)
    fw.service(clock.now_ns())
    assert m.aprd(0, 0x0110, 1).data[0] & 0x02
    assert fw.deadline_ns() == 1_000_000_000 + 100_000_000
    clock.advance(1_000_000)
    fw.service(clock.now_ns())
    assert not m.aprd(0, 0x0110, 1).data[0] & 0x02
    assert m.aprd(0, 0x0443, 1).data == b"\x01"
    assert fw.deadline_ns() is None
    spi(fw, 0x00, 0x00)  # any complete access reloads it
    assert m.aprd(0, 0x0110, 1).data[0] & 0x02
    assert m.aprd(0, 0x0443, 1).data == b"\x01"
    m.apwr(0, 0x0410, struct.pack("<H", 0))  # time 0: the watchdog is off
    spi(fw, 0x00, 0x00)
    assert fw.deadline_ns() is None
    del seg


@pytest.mark.parametrize("pin", [False, True])
def test_the_pdi_emulation_pin_until_the_eeprom_loads(pin: bool) -> None:
    """0x0141 bit 0: "1 with PDI_EMULATION pin, later EEPROM ADR 0x0000" (§5.26 Table 38)."""
    blank = Esc(0, FrameContext(), bytearray(b"\xff" * 256), pdi_emulation=pin)
    assert not blank.pdram_ok  # no valid EEPROM: the pin's value stands
    assert blank.mem[0x0141] & 0x01 == int(pin)
    seg, _ = segment_of(1, pdi_emulation=pin)
    assert seg.escs[0].mem[0x0141] & 0x01 == 0  # the default SII's word 0: emulation off


def read_system_time(fw: ExternalFirmware, addr: int = 0x0910, n: int = 8) -> int:
    """A 3-byte-addressed read with the wait state byte, as SOES's SPI drivers send it."""
    head = [addr >> 5, ((addr & 0x1F) << 3) | 6, ((addr >> 13) << 5) | (3 << 2), 0xFF]
    got = fw._transfer(bytes([*head, *bytes(n - 1), 0xFF]))  # a frame off the socket
    return int.from_bytes(got[4:], "little")


def test_a_pdi_read_of_0x0910_is_the_running_system_time(chip) -> None:  # type: ignore[no-untyped-def]
    """§5.50.2 Table 95: "PDI read access: Local copy of the System Time. Time latched when
    reading first byte (0x0910)"; with no master using DC the local clock still runs."""
    _, clock, m, fw = chip
    first = read_system_time(fw)
    # the slave's local clock starts at 1_000_003_000 ns, the host clock is at 1 s
    assert first == 1_000_003_000 + 1_000_000_000
    clock.advance(1_000_000)
    assert read_system_time(fw) == first + 1_000_000
    assert read_system_time(fw, n=4) == (first + 1_000_000) & 0xFFFFFFFF  # SOES reads 4 bytes
    # DC on: the master's offset (0x0920) is part of the system time the PDI reads
    m.apwr(0, 0x0920, struct.pack("<Q", 0x0000_0010_0000_0000))
    clock.advance(1_000_000)
    on = read_system_time(fw)
    assert on == first + 2_000_000 + 0x0000_0010_0000_0000
    clock.advance(1_000_000)
    assert read_system_time(fw) - on == 1_000_000
    # only a read that starts at 0x0910 latches: the upper half alone is the latched one
    clock.advance(5 << 32)
    assert read_system_time(fw, 0x0914, 4) == (on + 1_000_000) >> 32
    assert errors(m) == (0, 0)
