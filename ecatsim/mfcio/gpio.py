"""The general-purpose IO unit: eight pins, each an input or an output, with a safe state
for the outputs while the emergency switch is active.

Ref: TMC8460 §6.10 Table 150, §6.10.1-§6.10.4, §6.13; decision M18.
"""

from __future__ import annotations


class Gpio:
    """GPO_OUT_VAL (7:0 values, 15:8 safe state), GPIO_CONFIG (1 = output), GPI_IN_VAL."""

    def __init__(self) -> None:
        self.out_val = 0
        self.config = 0
        #: the level the world drives on each pin (a switch, a pull resistor); None: open
        self.external: list[int | None] = [None] * 8

    def write(self, name: str, value: int) -> None:
        if name == "GPO_OUT_VAL":
            self.out_val = value & 0xFFFF
        elif name == "GPIO_CONFIG":
            self.config = value & 0xFF
        else:
            raise KeyError(name)

    def driven(self, enabled: bool, emergency: bool) -> list[int | None]:
        """What the unit drives on each pin: None for inputs and while outputs are not
        enabled (not OP, §6.1); the safe state GPO_OUT_VAL[15:8] while nES is active,
        else GPO_OUT_VAL[7:0]. Ref: TMC8460 §6.10.3, §6.10.4."""
        out: list[int | None] = [None] * 8
        if not enabled:
            return out
        vals = self.out_val >> 8 if emergency else self.out_val
        for i in range(8):
            if self.config >> i & 1:
                out[i] = vals >> i & 1
        return out

    def in_val(self, pins: list[int | None]) -> int:
        """GPI_IN_VAL: the level on each pin (an open input reads 0, decision M18)."""
        v = 0
        for i, lvl in enumerate(pins):
            if lvl:
                v |= 1 << i
        return v
