"""The MFCIO IRQ unit: IRQ_CFG enables sources (and, bit 15, the nES input), IRQ_FLAGS
holds the events of the enabled sources; MFCIO_IRQ is their OR.

Ref: TMC8460 §6.12 Table 154, §6.13; decisions M19, M20.
"""

from __future__ import annotations

SRC_ENC_N = 0x0001
SRC_SD_TARGET = 0x0002
SRC_SPI_DATA = 0x0004
SRC_WD_TIMEOUT = 0x0008
SRC_PWM_START = 0x0010
SRC_PWM_CENTER = 0x0020
SRC_PWM_A = 0x0040
SRC_PWM_B = 0x0080
NES = 0x8000


class Irq:
    """IRQ_CFG and IRQ_FLAGS with the emergency flag's two-write reset."""

    def __init__(self) -> None:
        self.cfg = 0
        self.flags = 0
        #: IRQ_CFG bit 15 was written 0 since the emergency flag was set (first of the two
        #: writes that reset it, §6.13.2)
        self._nes_reset_half = False

    @property
    def nes_enabled(self) -> bool:
        """IRQ_CFG[15]: MFC_nES is active (must be driven high). Ref: §6.13.1."""
        return bool(self.cfg & NES)

    def write(self, name: str, value: int) -> None:
        """IRQ_CFG; bit 15 written 0 and then 1 clears the emergency flag. Ref: §6.13.2."""
        if name != "IRQ_CFG":
            raise KeyError(name)
        value &= 0x80FF
        if not value & NES:
            self._nes_reset_half = True
        elif not self.cfg & NES and self._nes_reset_half:
            self.flags &= ~NES
            self._nes_reset_half = False
        self.cfg = value

    def raise_(self, sources: int) -> None:
        """Events of ``sources``: flagged where IRQ_CFG enables them."""
        self.flags |= sources & self.cfg & 0xFF

    def emergency(self) -> None:
        """A falling edge on MFC_nES while enabled: IRQ_FLAGS[15]. Ref: TMC8460 §6.13.1."""
        if self.nes_enabled:
            self.flags |= NES
            self._nes_reset_half = False

    def read_flags(self) -> int:
        """IRQ_FLAGS; reading clears every flag but the emergency flag. Ref: §6.12."""
        v = self.flags
        self.flags &= NES
        return v

    @property
    def line(self) -> int:
        """The MFCIO_IRQ output: any flag set."""
        return 1 if self.flags else 0
