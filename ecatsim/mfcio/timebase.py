"""The MFCIO clocks: the 25 MHz unit clock and the 100 MHz PWM clock, as integer ticks of
the simulated nanosecond time (no floating point anywhere in the units).

Ref: TMC8460 §6.8 Table 145 (f_CLK 25 MHz, t_CLK 40 ns), §6.9 Table 148 (PWM f_CLK
100 MHz, t_CLK 10 ns), §6.7.8 (SPI timing in 25 MHz clocks), §6.11.2 Table 151 (WD_TIME
in 25 MHz clocks).
"""

from __future__ import annotations

F_CLK_HZ = 25_000_000
TICK_NS = 40
F_PWM_CLK_HZ = 100_000_000
PWM_TICK_NS = 10


def ticks(ns: int) -> int:
    """The 25 MHz clock edge at or before ``ns`` (edges at multiples of 40 ns)."""
    return ns // TICK_NS


def tick_ns(tick: int) -> int:
    """The time of a 25 MHz clock edge."""
    return tick * TICK_NS


def pwm_ticks(ns: int) -> int:
    """The 100 MHz clock edge at or before ``ns``."""
    return ns // PWM_TICK_NS


def ceil_div(a: int, b: int) -> int:
    """Integer ceiling of a / b for b > 0."""
    return -(-a // b)
