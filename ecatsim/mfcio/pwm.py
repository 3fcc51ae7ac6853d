"""The 3-channel PWM unit on its 100 MHz clock: one counter 0..PWM_MAXCNT for all
channels, on-time PWM_VALUE_n placed left, right or centred in the cycle and shifted by
PWM_CNTRSHIFT_n, chopper modes with brake-before-make, the trigger pulses and the
emergency switch off-state.

t_PWM = (1 + PWM_MAXCNT) * 10 ns; channel n is on for PWM_VALUE_n clocks per cycle
(duty PWM_VALUE_n / (1 + PWM_MAXCNT)); in complementary mode the high side comes on
PWM_BBM_H clocks after the low side went off and the low side PWM_BBM_L clocks after the
high side went off.

Ref: TMC8460 §6.9 Tables 146-149, §6.9.1-§6.9.13; decisions M15-M17.
"""

from __future__ import annotations

from dataclasses import dataclass, field

# PWM_ALIGNMENT bits 1..0. Ref: TMC8460 §6.9 Table 147.
ALIGN_OFF = 0b00
ALIGN_RIGHT = 0b01
ALIGN_LEFT = 0b10
ALIGN_CENTER = 0b11

# PWM_POLARITIES bits. Ref: Table 147.
POL_LS = 0x01
POL_HS = 0x02
POL_AB = 0x04
POL_B = 0x08
POL_CENTER = 0x10
POL_A = 0x20
POL_ZERO = 0x40

#: the marks that trigger SPI transfers (SPI_CONF 10..8) and IRQs (IRQ_CFG bits 4-7)
MARK_START = 1
MARK_CENTER = 2
MARK_A = 3
MARK_B = 4

PWM_REGS = (
    "PWM_MAXCNT",
    "PWM_CHOPMODE",
    "PWM_ALIGNMENT",
    "PWM_POLARITIES",
    "PWM_VALUE_0",
    "PWM_VALUE_1",
    "PWM_VALUE_2",
    "PWM_CNTRSHIFT_0",
    "PWM_CNTRSHIFT_1",
    "PWM_CNTRSHIFT_2",
    "PWM_PULSE_A",
    "PWM_PULSE_B",
    "PWM_PULSE_LENGTH",
    "PWM_BBM_H",
    "PWM_BBM_L",
)
_MASKS = {
    "PWM_MAXCNT": 0x0FFF,
    "PWM_CHOPMODE": 0x0777,
    "PWM_ALIGNMENT": 0x03,
    "PWM_POLARITIES": 0x7F,
    "PWM_PULSE_LENGTH": 0xFF,
    "PWM_BBM_H": 0xFF,
    "PWM_BBM_L": 0xFF,
}


@dataclass
class PwmOutputs:
    """The unit's output levels at one instant (before the AL-state and watchdog gating)."""

    hs: list[int] = field(default_factory=lambda: [0, 0, 0])
    ls: list[int] = field(default_factory=lambda: [0, 0, 0])
    zero: int = 0
    center: int = 0
    a: int = 0
    b: int = 0
    ab: int = 0


class Pwm:
    """The PWM unit. Clocks are 100 MHz ticks."""

    def __init__(self) -> None:
        self.r: dict[str, int] = dict.fromkeys(PWM_REGS, 0)
        self.origin = 0  # a clock at which a cycle started (counter 0)
        self.emergency = False

    # ------------------------------------------------------------------ registers

    @property
    def period(self) -> int:
        """Clocks per cycle: 1 + PWM_MAXCNT. Ref: TMC8460 §6.9 Table 148."""
        return self.r["PWM_MAXCNT"] + 1

    def write(self, name: str, value: int, tick: int) -> None:
        """Take a register at ``tick`` (a new PWM_MAXCNT starts a new cycle there,
        decision M16)."""
        if name not in self.r:
            raise KeyError(name)
        value &= _MASKS.get(name, 0x0FFF)
        if name == "PWM_MAXCNT" and value != self.r[name]:
            self.origin = tick
        self.r[name] = value

    # ------------------------------------------------------------------ timing

    def counter(self, tick: int) -> int:
        return (tick - self.origin) % self.period

    def next_start(self, tick: int) -> int:
        """The first cycle start strictly after ``tick``."""
        return tick + self.period - self.counter(tick)

    def duty_clocks(self, ch: int) -> int:
        """On-time of channel ``ch`` in clocks per cycle (PWM_VALUE_n, at most a cycle)."""
        if self.r["PWM_ALIGNMENT"] == ALIGN_OFF:
            return 0
        return min(self.r[f"PWM_VALUE_{ch}"], self.period)

    def duty(self, ch: int) -> tuple[int, int]:
        """Duty cycle of channel ``ch`` as (on clocks, cycle clocks). Ref: §6.9.5."""
        return self.duty_clocks(ch), self.period

    def on_start(self, ch: int) -> int:
        """Counter value at which channel ``ch`` turns on: left 0, right period - value,
        centred (period - value) // 2, each plus PWM_CNTRSHIFT_n (mod period).
        Ref: TMC8460 §6.9.3 (Figures 36-38), §6.9.9 (Figure 40); decision M15."""
        p = self.period
        v = self.duty_clocks(ch)
        al = self.r["PWM_ALIGNMENT"]
        start = 0 if al == ALIGN_LEFT else p - v if al == ALIGN_RIGHT else (p - v) // 2
        return (start + self.r[f"PWM_CNTRSHIFT_{ch}"]) % p

    def pwm_on(self, ch: int, c: int) -> bool:
        v = self.duty_clocks(ch)
        return (c - self.on_start(ch)) % self.period < v

    def bridge(self, ch: int, c: int) -> tuple[int, int]:
        """(high side, low side) on/off of channel ``ch`` at counter ``c``: Table 149's
        chopper modes; %111 complementary with BBM_H before the high side comes on and
        BBM_L before the low side does. Ref: TMC8460 §6.9.2, §6.9.10-§6.9.12."""
        mode = (self.r["PWM_CHOPMODE"] >> (4 * ch)) & 0x7
        if self.emergency:
            return 0, 0  # §6.9.13: nES brings both sides into the off state
        if mode == 0b001:
            return 0, 1
        if mode == 0b010:
            return 1, 0
        if mode not in (0b101, 0b110, 0b111):
            return 0, 0
        p = self.period
        v = self.duty_clocks(ch)
        off = (c - self.on_start(ch)) % p  # clocks since the PWM signal went on
        on = off < v
        if mode == 0b101:
            return 0, int(on)
        if mode == 0b110:
            return int(on), 0
        hs = on and off >= self.r["PWM_BBM_H"]
        ls = not on and off >= v + self.r["PWM_BBM_L"]
        if v == 0:  # never on: the low side stays on (no edge, no gap)
            ls = True
        elif v >= p:  # always on: no low-side phase
            hs, ls = True, False
        return int(hs), int(ls)

    def mark_pos(self, kind: int) -> int:
        """Counter value of a mark: start 0, centre period // 2, PULSE_A, PULSE_B."""
        if kind == MARK_START:
            return 0
        if kind == MARK_CENTER:
            return self.period // 2
        return self.r["PWM_PULSE_A" if kind == MARK_A else "PWM_PULSE_B"] % self.period

    def next_mark(self, kind: int, tick: int) -> int:
        """The first clock >= ``tick`` at which the counter stands at the mark."""
        return tick + (self.mark_pos(kind) - self.counter(tick)) % self.period

    def marks_between(self, t0: int, t1: int) -> set[int]:
        """Marks that occurred in (t0, t1] (none while the unit is off)."""
        if self.r["PWM_ALIGNMENT"] == ALIGN_OFF or t1 <= t0:
            return set()
        return {k for k in (1, 2, 3, 4) if self.next_mark(k, t0 + 1) <= t1}

    def _pulse(self, pos: int, c: int) -> int:
        return int((c - pos) % self.period < self.r["PWM_PULSE_LENGTH"])

    def outputs(self, tick: int) -> PwmOutputs:
        """All output levels at ``tick``, polarities applied (1 = pin high). Ref: §6.9.4,
        Table 146 (PULSE_AB = PULSE_A or PULSE_B), §6.9.8 (pulse length)."""
        pol = self.r["PWM_POLARITIES"]
        o = PwmOutputs()
        c = self.counter(tick)
        running = self.r["PWM_ALIGNMENT"] != ALIGN_OFF
        for ch in range(3):
            hs, ls = self.bridge(ch, c) if running or self.emergency else (0, 0)
            if not running and not self.emergency:
                mode = (self.r["PWM_CHOPMODE"] >> (4 * ch)) & 0x7
                hs, ls = (1, 0) if mode == 0b010 else (0, 1) if mode == 0b001 else (0, 0)
            o.hs[ch] = hs ^ (1 if pol & POL_HS else 0)
            o.ls[ch] = ls ^ (1 if pol & POL_LS else 0)
        if running:
            z = self._pulse(0, c)
            ce = self._pulse(self.period // 2, c)
            a = self._pulse(self.mark_pos(MARK_A), c)
            b = self._pulse(self.mark_pos(MARK_B), c)
        else:
            z = ce = a = b = 0
        o.zero = z ^ (1 if pol & POL_ZERO else 0)
        o.center = ce ^ (1 if pol & POL_CENTER else 0)
        o.a = a ^ (1 if pol & POL_A else 0)
        o.b = b ^ (1 if pol & POL_B else 0)
        o.ab = (a | b) ^ (1 if pol & POL_AB else 0)
        return o
