"""Process-data and PDI watchdogs.

The basic increment is (divider + 2) ticks of 25 MHz; the process-data watchdog is
restarted by every ECAT write to an SM with the watchdog trigger bit, and expires
``time_pd`` increments later. Ref: TMC8460 §5.39-5.44 Tables 53-58.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ecatsim.esc.regs import (  # compiled: C constants (watchdog.pxd)
    EV_WATCHDOG_PD,
    WD_COUNTER_PD,
    WD_COUNTER_PDI,
    WD_DIVIDER,
    WD_STATUS_PD,
    WD_TIME_PD,
)

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc

TICK_NS = 40  # 25 MHz


class Watchdog:
    """Process-data watchdog state (the registers live in ESC memory), and the hooks of
    the watchdog registers 0x0400-0x0443 (the ESC ``esc`` gives the AL event register)."""

    __slots__ = ("ctx", "deadline_ns", "esc", "increment_ns", "mem", "timeout_ns")

    def __init__(self, esc: Esc) -> None:
        self.esc = esc
        self.ctx = esc.ctx  # its earliest deadline the segment's (``wd_next``, P100)
        self.mem = esc.mem
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
            d = now_ns + self.timeout_ns
            self.deadline_ns = d
            ctx = self.ctx
            if d < ctx.wd_next:  # earlier than any the schedule knows of (P100)
                ctx.wd_next = d
        p = self.mem  # compiled: a C pointer (a register of the ESC's memory): no raise
        p[WD_STATUS_PD] |= 0x01

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

    # -- register hooks (ecatsim/esc/dispatch.py: side_effect wd.<name>) -----------------

    def _ec_divider(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.39 Table 53."""
        self.reconfigure()

    def _ec_time_pdi(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.40 Table 54 (the PDI watchdog is kept reloaded by the firmware:
        Esc.set_pdi_watchdog)."""

    def _ec_time_pd(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.41 Table 55."""
        self.reconfigure()

    def _pr_status_pd(self, ra: int, rs: int) -> None:
        """PDI read of 0x0440 clears AL event 0x0220.6. Ref: TMC8460 §5.42 Table 56 note *."""
        self.esc.clr_al_event(EV_WATCHDOG_PD)

    def _ew_counter(self, ra: int, rs: int, old: bytes) -> None:
        """Writing either watchdog counter clears both. Ref: TMC8460 §5.43, §5.44 Tables
        57, 58."""
        self.mem[WD_COUNTER_PD] = 0
        self.mem[WD_COUNTER_PDI] = 0
