"""The MFCIO IO watchdog: a counter of 25 MHz clocks from the last retrigger; at WD_TIME the
masked outputs take their safe levels and output enables until a retrigger (or, with
cfg_persistent, until WD_TIME is written again). WD_MAX keeps the highest count reached.

Ref: TMC8460 §6.11.1, §6.11.2 Tables 151-153; decision M21.
"""

from __future__ import annotations

CFG_PERSISTENT = 0x01
CFG_PDI_CSN = 0x02
CFG_MFC_CSN = 0x04
CFG_SOF = 0x08
CFG_IN_EDGE = 0x10
CFG_ACTIVE = 0x80  # read only: a timeout is active

#: output lines of WD_OUT_MASK_POL / WD_OE_POL, bit by bit. Ref: Table 152.
OUTPUT_LINES = (
    *(f"GPO{i}" for i in range(8)),
    "PWM_LS0",
    "PWM_LS1",
    "PWM_LS2",
    "PWM_HS0",
    "PWM_HS1",
    "PWM_HS2",
    "PWM_PULSE_AB",
    "PWM_PULSE_B",
    "PWM_PULSE_CENTER",
    "PWM_PULSE_A",
    "PWM_PULSE_START",
    "SD_DIR",
    "SD_STP",
    "SPI_CS3",
    "SPI_CS2",
    "SPI_CS1",
    "SPI_CS0",
    "SPI_SDI",
    "SPI_SCK",
)
#: input lines of WD_IN_MASK_POL, bit by bit. Ref: Table 153.
INPUT_LINES = (*(f"GPI{i}" for i in range(8)), "SPI_SDO", "ABN_N", "ABN_B", "ABN_A")


class IoWatchdog:
    """WD_TIME/WD_CFG/WD_OUT_MASK_POL/WD_OE_POL/WD_IN_MASK_POL and WD_MAX."""

    def __init__(self) -> None:
        self.time = 0
        self.cfg = 0
        self.out_mask_pol = 0
        self.oe_pol = 0
        self.in_mask_pol = 0
        self.start = 0  # clock of the last retrigger (the counter's zero)
        self.max = 0
        self.active = False
        self.expired_at: int | None = None
        self.timeouts = 0  # expiries not yet seen by the IRQ unit
        self._cond: bool | None = None  # the input condition at the last look

    # ------------------------------------------------------------------ registers

    def write(self, name: str, value: int, tick: int) -> None:
        """Writing WD_TIME restarts the counter, resets WD_MAX and ends a persistent
        timeout. Ref: TMC8460 §6.11.2 Table 151."""
        self.advance(tick)
        if name == "WD_TIME":
            self.time = value & 0xFFFFFFFF
            self.start = tick
            self.max = 0
            self.active = False
            self.expired_at = None
        elif name == "WD_CFG":
            self.cfg = value & 0x1F
        elif name == "WD_OUT_MASK_POL":
            self.out_mask_pol = value & ((1 << 64) - 1)
        elif name == "WD_OE_POL":
            self.oe_pol = value & 0xFFFFFFFF
        elif name == "WD_IN_MASK_POL":
            self.in_mask_pol = value & 0xFFFFFFFF
        else:
            raise KeyError(name)

    @property
    def cfg_readback(self) -> int:
        """WD_CFG when read: bit 7 = a timeout is active."""
        return self.cfg | (CFG_ACTIVE if self.active else 0)

    # ------------------------------------------------------------------ time

    def deadline(self) -> int | None:
        """The clock at which the counter reaches WD_TIME, if it is running."""
        if self.time == 0 or self.active:
            return None
        return self.start + self.time

    def advance(self, tick: int) -> None:
        """Count to ``tick``: WD_MAX follows the counter, WD_TIME expires it."""
        if self.time == 0:
            return
        d = self.start + self.time
        if not self.active and tick >= d:
            self.active = True
            self.expired_at = d
            self.timeouts += 1
            self.max = max(self.max, self.time)
        if not self.active:
            self.max = max(self.max, tick - self.start)

    def retrigger(self, tick: int) -> None:
        """A trigger event: the counter restarts; a non-persistent timeout ends."""
        self.advance(tick)
        if self.time and not self.active:
            self.max = max(self.max, tick - self.start)
        if self.active and self.cfg & CFG_PERSISTENT:
            return
        self.active = False
        self.start = tick

    def event(self, kind: int, tick: int) -> None:
        """A start of frame (CFG_SOF) or a rising CSN edge (CFG_PDI_CSN, CFG_MFC_CSN)."""
        if self.cfg & kind:
            self.retrigger(tick)

    def inputs(self, levels: int, tick: int) -> None:
        """The input lines (bit i = line i of Table 153): all selected lines at their
        polarity is the condition; its rising (cfg_in_edge = 1) or falling edge retriggers.
        Ref: TMC8460 §6.11.1 (edge sensitive), Table 151 (WD_IN_MASK_POL)."""
        mask = self.in_mask_pol >> 16 & 0xFFFF
        if not mask:
            self._cond = None
            return
        pol = self.in_mask_pol & 0xFFFF
        cond = (levels ^ pol) & mask == 0
        was = self._cond
        self._cond = cond
        if was is None or was == cond:
            return
        if cond == bool(self.cfg & CFG_IN_EDGE):
            self.retrigger(tick)

    # ------------------------------------------------------------------ action

    def force(self, line: int) -> tuple[int, int] | None:
        """(level, output enable) forced on output ``line`` during a timeout, or None."""
        if not self.active or not (self.out_mask_pol >> (32 + line)) & 1:
            return None
        return (self.out_mask_pol >> line) & 1, (self.oe_pol >> line) & 1
