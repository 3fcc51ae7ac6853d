"""The MFCIO configuration bytes: ECAT access and shadow trigger source per register, and
the category-1 EEPROM vector they are loaded from.

Ref: TMC8460 §6.4 Tables 135 (configuration byte) and 136 (trigger sources), §6.3
Table 134 (EEPROM parameter map), §5.47 Table 74 (parameter RAM 0x0580+y).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ecatsim.mfcio.regs import N_CONFIGURED, REGISTERS

#: the category type the TMC8460 loads into 0x0580 when it is the first category at word
#: 0x40. Ref: TMC8460 §6.3.
CATEGORY_TYPE = 1
CATEGORY_WORD = 0x40

#: configuration byte bit 4. Ref: Table 135.
ECAT_ACCESS = 0x10
TRIGGER_MASK = 0x0F


class Trigger(IntEnum):
    """Shadow trigger source, configuration byte bits 3..0. Ref: TMC8460 §6.4 Table 136."""

    ALWAYS = 0
    SYNC0 = 1
    SYNC1 = 2
    LATCH0 = 3
    LATCH1 = 4
    SOF = 5
    EOF = 6
    PDI_CS = 7
    PDI_DESELECT = 8
    MFC_CS = 9
    MFC_DESELECT = 10
    BEFORE_CYCLE = 11
    AFTER_CYCLE = 12
    PWM_CYCLE = 13
    ON_CHANGE = 14
    ALWAYS_15 = 15


#: Table 136 texts, for ``eeprom show`` and ``esi export``
TRIGGER_TEXT = {
    Trigger.ALWAYS: "always",
    Trigger.SYNC0: "SYNC0 signal",
    Trigger.SYNC1: "SYNC1 signal",
    Trigger.LATCH0: "LATCH0 signal",
    Trigger.LATCH1: "LATCH1 signal",
    Trigger.SOF: "start of frame",
    Trigger.EOF: "end of frame",
    Trigger.PDI_CS: "PDI-SPI chip select",
    Trigger.PDI_DESELECT: "PDI-SPI chip deselect",
    Trigger.MFC_CS: "MFC-CTRL-SPI chip select",
    Trigger.MFC_DESELECT: "MFC-CTRL-SPI chip deselect",
    Trigger.BEFORE_CYCLE: "before shadow register handling cycle",
    Trigger.AFTER_CYCLE: "after shadow register handling cycle",
    Trigger.PWM_CYCLE: "start of MFC PWM cycle",
    Trigger.ON_CHANGE: "when data value changes",
    Trigger.ALWAYS_15: "always",
}


@dataclass(frozen=True, slots=True)
class RegConfig:
    """One register's configuration byte. Ref: TMC8460 §6.4 Table 135."""

    ecat: bool
    trigger: Trigger

    @classmethod
    def of(cls, byte: int) -> RegConfig:
        return cls(bool(byte & ECAT_ACCESS), Trigger(byte & TRIGGER_MASK))

    @property
    def byte(self) -> int:
        return (ECAT_ACCESS if self.ecat else 0) | int(self.trigger)


def vector(raw: bytes | bytearray) -> bytes:
    """The 44 configuration bytes from a category-1 body: bytes beyond 44 are ignored, a
    shorter vector is completed with the reset value 0x00 (§6.4: trailing bytes for unused
    registers may be omitted); bits 7..5 are reserved and read 0 (Table 74)."""
    v = bytes(b & 0x1F for b in raw[:N_CONFIGURED])
    return v.ljust(N_CONFIGURED, b"\x00")


def category_body(config: bytes) -> bytes:
    """The category-1 data for a configuration vector: trailing 0x00 bytes dropped (§6.4),
    padded to whole words as every SII category is (ETG.2010 §2.3)."""
    body = bytes(config[:N_CONFIGURED]).rstrip(b"\x00")
    return body + b"\x00" if len(body) % 2 else body


def describe(config: bytes) -> list[str]:
    """One line per register, for ``ecatsim eeprom show`` and ``esi export``: number,
    name, direction, ECAT access or MFC CTRL SPI, trigger, and the PDRAM address."""
    v = vector(config)
    lines = []
    for r in REGISTERS[:N_CONFIGURED]:
        b = v[r.num]
        c = RegConfig.of(b)
        where = f"0x{r.mb:04X}" if r.mb is not None else "-"
        if b == 0:
            what = "unused (0x00)"
        elif c.ecat:
            what = f"ECAT {'MB0' if r.writable else 'MB1'} {where}"
        else:
            what = "MFC CTRL SPI" if r.writable else "MFC CTRL SPI only (not in MB1)"
        lines.append(
            f"  {r.num:2d} {r.name:<17} {'W' if r.writable else 'R'} 0x{b:02X} {what}, "
            f"trigger {int(c.trigger)} ({TRIGGER_TEXT[c.trigger]})"
        )
    return lines
