"""Byte layouts of the TMC211 frames (TMC211 §6.8, §6.9, §6.11).

The sheet numbers a frame's bytes from the identifier (byte 0); here ``data[0]`` is the
sheet's byte 1. Position fields are big-endian two's complement in 1/16 micro-steps
(§7.3 FAQ). The command byte's bit 7 is "1" in every table; it is not checked.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the AppCMD byte of frames on the reserved identifier 0x3C (§6.9.5, §6.9.10)
APP_CMD = 0x80
#: the first data byte of the LIN sleep command on 0x3C (§6.11.15)
SLEEP_BYTE = 0x00
FILL = 0xFF


def s16(hi: int, lo: int) -> int:
    """A signed 16-bit value from two bytes."""
    v = hi << 8 | lo
    return v - 0x10000 if v & 0x8000 else v


def u16(v: int) -> tuple[int, int]:
    """A 16-bit value (any sign) as two bytes."""
    v &= 0xFFFF
    return v >> 8, v & 0xFF


def sign11(v: int) -> int:
    """An 11-bit two's complement field as an int."""
    v &= 0x7FF
    return v - 0x800 if v & 0x400 else v


def secpos_units(secpos: int) -> int:
    """SecPos[10:0]: the 11 MSBs of a 16-bit position, LSBs 0 (§5.2.1, §7.3 FAQ)."""
    return sign11(secpos) << 5


def short_units(pos: int) -> int:
    """A SetPositionShort 11-bit position in half-steps, in 1/16 micro-steps (§7.3)."""
    return sign11(pos) << 3


@dataclass(frozen=True, slots=True)
class MotorParams:
    """The motor parameters of SetMotorParam and GetFullStatus (§6.11.10, §6.11.2)."""

    irun: int = 0
    ihold: int = 0
    vmax: int = 0
    vmin: int = 0
    secpos: int = 0
    shaft: int = 0
    acc: int = 0
    accshape: int = 0
    stepmode: int = 0


def decode_motor_params(p: bytes) -> MotorParams:
    """SetMotorParam bytes 4..8 (§6.11.10)."""
    return MotorParams(
        irun=p[0] >> 4,
        ihold=p[0] & 0xF,
        vmax=p[1] >> 4,
        vmin=p[1] & 0xF,
        secpos=(p[2] >> 5) << 8 | p[3],
        shaft=p[2] >> 4 & 1,
        acc=p[2] & 0xF,
        accshape=p[4] >> 4 & 1,
        stepmode=p[4] >> 2 & 3,
    )


def encode_motor_params(m: MotorParams) -> bytes:
    """SetMotorParam bytes 4..8 (§6.11.10); the fixed bits are 1."""
    return bytes(
        (
            m.irun << 4 | m.ihold,
            m.vmax << 4 | m.vmin,
            (m.secpos >> 8 & 7) << 5 | m.shaft << 4 | m.acc,
            m.secpos & 0xFF,
            0xE3 | m.accshape << 4 | m.stepmode << 2,
        )
    )


@dataclass(frozen=True, slots=True)
class Flags:
    """The status flags of §5.2.2 as a node reports them."""

    vddreset: int = 0
    steploss: int = 0
    eldef: int = 0
    uv2: int = 0
    tsd: int = 0
    tw: int = 0
    tinfo: int = 0
    motion: int = 0
    esw: int = 0
    ovc1: int = 0
    ovc2: int = 0
    cpfail: int = 0


def status_byte(f: Flags) -> int:
    """VddReset StepLoss ElDef UV2 TSD TW Tinfo[1:0] (§6.11.1, §6.11.2, §6.11.4)."""
    return (
        f.vddreset << 7 | f.steploss << 6 | f.eldef << 5 | f.uv2 << 4 | f.tsd << 3 | f.tw << 2
    ) | f.tinfo


def get_actual_pos_direct(ad: int, actpos: int, f: Flags) -> bytes:
    """GetActualPos type #5 answer: ESW|AD, ActPos, status (§6.11.1)."""
    return bytes((f.esw << 7 | ad, *u16(actpos), status_byte(f)))


def get_actual_pos_indirect(ad: int, actpos: int, f: Flags) -> bytes:
    """GetActualPos type #6 answer: 1|AD, ActPos, status, four 0xFF (§6.11.1)."""
    return bytes((0x80 | ad, *u16(actpos), status_byte(f), FILL, FILL, FILL, FILL))


def get_status(ad: int, f: Flags) -> bytes:
    """GetStatus type #5 answer: ESW|AD, status (§6.11.4)."""
    return bytes((f.esw << 7 | ad, status_byte(f)))


def full_status_1(ad: int, m: MotorParams, f: Flags, lin_errors: int) -> bytes:
    """GetFullStatus reading frame 1 (§6.11.2)."""
    return bytes(
        (
            0x80 | ad,
            m.irun << 4 | m.ihold,
            m.vmax << 4 | m.vmin,
            m.accshape << 7 | m.stepmode << 5 | m.shaft << 4 | m.acc,
            status_byte(f),
            f.motion << 5 | f.esw << 4 | f.ovc1 << 3 | f.ovc2 << 2 | 0x02 | f.cpfail,
            lin_errors & 0x0F,
            FILL,
        )
    )


def full_status_2(ad: int, actpos: int, tagpos: int, secpos: int) -> bytes:
    """GetFullStatus reading frame 2 (§6.11.2)."""
    return bytes(
        (0x80 | ad, *u16(actpos), *u16(tagpos), secpos & 0xFF, 0xF8 | secpos >> 8 & 7, FILL)
    )


def otp_param(shadow: bytes, hw: int) -> bytes:
    """GetOTPParam answer: the OTP bytes, HW2..HW0 in bits 6:4 of byte 0x02 (§6.11.3)."""
    b2 = shadow[2] & 0x8F | (hw >> 2 & 1) << 6 | (hw >> 1 & 1) << 5 | (hw & 1) << 4
    return bytes((shadow[0], shadow[1], b2, *shadow[3:8]))


def pack_dynamic_ids(pairs: list[tuple[int, int]]) -> bytes:
    """Bytes 4..8 of the 0x3C dynamic-ID frame from (ROM pointer, identifier) pairs (§6.8).

    The four (ROMp_x[3:0], DynID_x[5:0]) pairs are packed least significant bit first;
    missing pairs are filled with ROM pointer 0xF and identifier 0x3F (nothing)."""
    bits = 0
    filled = [*pairs, *[(0xF, 0x3F)] * (4 - len(pairs))]
    for i, (rom, ident) in enumerate(filled[:4]):
        bits |= (rom & 0xF | (ident & 0x3F) << 4) << 10 * i
    return bits.to_bytes(5, "little")


def unpack_dynamic_ids(data: bytes) -> list[tuple[int, int]]:
    """(ROM pointer, identifier) pairs from bytes 4..8 of the dynamic-ID frame (§6.8)."""
    bits = int.from_bytes(data[:5], "little")
    return [(bits >> 10 * i & 0xF, bits >> (10 * i + 4) & 0x3F) for i in range(4)]
