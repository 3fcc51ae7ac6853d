"""The TMC211 OTP memory: eight one-time-programmable bytes, zapped one byte at a time.

Ref: TMC211 §5.2.3 Table 9 (structure), Table 10 (lock bits), §6.11.11 (SetOTPParam),
§6.5 Table 13 (physical address). A zapped bit reads 1 and never returns to 0; a zap
persists to the node's OTP file, written atomically (decision N13).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ecatsim.errors import UserError
from ecatsim.files import atomic_write

OTP_SIZE = 8
#: byte 0x07: bit 1 LOCKBT protects 0x00-0x01, bit 0 LOCKBG protects 0x02-0x07 (Table 10)
LOCKBT = 0x02
LOCKBG = 0x01


@dataclass(frozen=True, slots=True)
class OtpParams:
    """The fields of Table 9 that load the RAM (ResetToDefault, power-on)."""

    irun: int
    ihold: int
    vmax: int
    vmin: int
    secpos: int
    shaft: int
    acc: int
    stepmode: int
    adm: int
    pa: int


def decode(cells: bytes) -> OtpParams:
    """Table 9: the OTP bytes as fields."""
    return OtpParams(
        irun=cells[3] >> 4,
        ihold=cells[3] & 0xF,
        vmax=cells[4] >> 4,
        vmin=cells[4] & 0xF,
        secpos=(cells[5] >> 5) << 8 | cells[6],
        shaft=cells[5] >> 4 & 1,
        acc=cells[5] & 0xF,
        stepmode=cells[7] >> 2 & 3,
        adm=cells[2] >> 7,
        pa=cells[2] & 0xF,
    )


def physical_address(adm: int, pa: int, hw: int) -> int:
    """AD[6:0] from ADM, PA[3:0] and the pins HW0..HW2 (bit 0..2 of ``hw``), Table 13."""
    hw0, hw1, hw2 = hw & 1, hw >> 1 & 1, hw >> 2 & 1
    if adm == 0:
        return hw0 << 6 | hw1 << 5 | hw2 << 4 | pa & 0xF
    return (pa & 1) << 6 | hw0 << 5 | hw1 << 4 | hw2 << 3 | (pa >> 1) & 0x7


class Otp:
    """The OTP cells, their shadow the logic reads, and the file that keeps them."""

    def __init__(self, initial: bytes, path: Path | None = None) -> None:
        self.path = path
        cells = bytes(initial)
        if path is not None and path.exists():
            try:
                cells = path.read_bytes()
            except OSError as exc:
                raise UserError(f"{path}: cannot read the OTP file ({exc.strerror})") from exc
            if len(cells) != OTP_SIZE:
                raise UserError(
                    f"{path}: an OTP file holds exactly {OTP_SIZE} bytes, this one "
                    f"{len(cells)}; delete it to start from the configured OTP"
                )
        self.cells = bytearray(cells)
        #: what the logic reads; refreshed at power-on, GetOTPParam and ResetToDefault
        #: (Table 8 "OTP refresh")
        self.shadow = bytes(self.cells)
        self.zaps = 0

    def refresh(self) -> None:
        self.shadow = bytes(self.cells)

    def locked(self, addr: int) -> bool:
        """Table 10: LOCKBT guards 0x00-0x01, LOCKBG guards 0x02-0x07."""
        return bool(self.cells[7] & (LOCKBT if addr < 2 else LOCKBG))

    def zap(self, addr: int, data: int) -> bool:
        """SetOTPParam: set the 1 bits of ``data`` at ``addr`` (0..7) unless locked.

        Bits already at 1 are left alone (§5.2.3: zapping them is disabled); bits at 0 in
        ``data`` do nothing. Returns whether any cell changed (and was persisted)."""
        addr &= 7
        if self.locked(addr):
            return False
        new = self.cells[addr] | data & 0xFF
        if new == self.cells[addr]:
            return False
        self.cells[addr] = new
        self.zaps += 1
        if self.path is not None:
            atomic_write(self.path, bytes(self.cells))
        return True

    def programmed(self) -> bool:
        """Whether motor parameters were zapped (bytes 0x03-0x06, StepMode in 0x07): an
        unprogrammed OTP leaves positioning commands ignored (§5.2.3 note)."""
        return any(self.shadow[3:7]) or bool(self.shadow[7] & 0x0C)
