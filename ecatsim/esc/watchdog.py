"""Process-data and PDI watchdogs.

The basic increment is (divider + 2) ticks of 25 MHz; the process-data watchdog is
restarted by every ECAT write to an SM with the watchdog trigger bit, and expires
``time_pd`` increments later. Ref: TMC8460 §5.39-5.44 Tables 53-58.
"""

from __future__ import annotations

from ecatsim.esc.regs import (  # compiled: C constants (watchdog.pxd)
    WD_COUNTER_PD,
    WD_DIVIDER,
    WD_STATUS_PD,
    WD_TIME_PD,
)

TICK_NS = 40  # 25 MHz


class Watchdog:
    """Process-data watchdog state (the registers live in ESC memory)."""

    __slots__ = ("deadline_ns", "increment_ns", "mem", "timeout_ns")

    def __init__(self, mem: bytearray) -> None:
        self.mem = mem
        self.deadline_ns = 0  # 0: not running
        self.increment_ns = 0
        self.timeout_ns = 0
        self.reconfigure()

    def reconfigure(self) -> None:
        """Recompute the increment and timeout from 0x0400 and 0x0420.

        Ref: TMC8460 §5.39 Table 53, §5.41 Table 55 (time 0 disables the watchdog).
        """
        m = self.mem
        div = m[WD_DIVIDER] | (m[WD_DIVIDER + 1] << 8)
        self.increment_ns = (div + 2) * TICK_NS
        t = m[WD_TIME_PD] | (m[WD_TIME_PD + 1] << 8)
        self.timeout_ns = t * self.increment_ns
        if self.timeout_ns == 0:
            self.deadline_ns = 0
            m[WD_STATUS_PD] |= 0x01  # "active or disabled"

    def trigger(self, now_ns: int) -> None:
        """Restart on an SM write. Ref: TMC8460 §5.41 Table 55."""
        if self.timeout_ns:
            self.deadline_ns = now_ns + self.timeout_ns
        self.mem[WD_STATUS_PD] |= 0x01

    def expired(self, now_ns: int) -> bool:
        """Check for expiry; on expiry update status and counter and return True.

        Ref: TMC8460 §5.42 Table 56, §5.43 Table 57 (counter saturates at 0xFF).
        """
        if self.deadline_ns == 0 or now_ns < self.deadline_ns:
            return False
        self.deadline_ns = 0
        m = self.mem
        m[WD_STATUS_PD] &= 0xFE
        if m[WD_COUNTER_PD] < 0xFF:
            m[WD_COUNTER_PD] += 1
        return True
