"""The step/direction unit: a 32-bit accumulator at 25 MHz makes the step pulses, a counter
counts them, a target stops them.

Step n after a (re)start at clock T_w comes at
``T_w + (SD_DLY + 1) + 2 + ceil(n * 2^32 / |SD_SR|)``: Table 145's t_STEP1st for n = 1
(2^32/SR clocks of accumulation, SD_DLY + 1 clocks of step-to-direction delay, 2 clocks
of processing) and t_STEP = 2^32/SR between steps, f_STEP = f_CLK / 2^32 * SR, all in
integer clocks. Each carry out of the accumulator is one step (decision M5).

Ref: TMC8460 §6.8 Tables 143-145, §6.8.1-§6.8.7; decisions M4-M8.
"""

from __future__ import annotations

from dataclasses import dataclass

from ecatsim.mfcio.timebase import F_CLK_HZ, ceil_div

ACC_ONE = 1 << 32
#: clocks between the write and the start of accumulation besides SD_DLY: "+1" and
#: "+2 clocks to pulse length" of Table 145's t_STEP1st
START_LATENCY = 3

# SD_CFG bits. Ref: TMC8460 §6.8 Table 144.
CFG_ENABLE = 0x01
CFG_CONTINUOUS = 0x02
CFG_STEP_POL = 0x04
CFG_DIR_POL = 0x08
CFG_CLEAR_COUNT = 0x10
CFG_TOGGLE = 0x20


def sr_for(f_step_hz: int) -> int:
    """The accumulation constant for a step frequency (rounded toward zero):
    SR = int(2^32 * f_STEP / f_CLK), Table 145 solved for SR. §6.8.1 prints the inverse
    (2^32 * f_CLK / f_STEP); decision M4."""
    if f_step_hz < 0:
        return -sr_for(-f_step_hz)
    return (f_step_hz << 32) // F_CLK_HZ


def f_step_mhz(sr: int) -> float:
    """f_STEP = f_CLK / 2^32 * SR in mHz (for display only). Ref: Table 145."""
    return F_CLK_HZ * 1000 * abs(sr) / ACC_ONE


def _signed32(v: int) -> int:
    v &= 0xFFFFFFFF
    return v - ACC_ONE if v & 0x80000000 else v


@dataclass
class StepEvent:
    """What one advance produced: signed steps, and the clock of the target-reached pulse."""

    steps: int = 0
    target_reached_at: int | None = None


class StepDir:
    """One step/direction channel. Registers are taken with :meth:`write` (a value change
    is a write, decision M2); time moves with :meth:`advance` (25 MHz clocks)."""

    def __init__(self) -> None:
        self.sr = 0  # signed accumulation constant (SD_SR)
        self.st = 0  # steps to be done (SD_ST as written)
        self.sl = 0  # step pulse length - 1 (SD_SL)
        self.dly = 0  # step-to-direction delay (SD_DLY)
        self.cfg = 0  # SD_CFG
        self.sc = 0  # step counter SD_SC (two's complement, 32 bit)
        self.remaining = 0  # steps left in n-pulse mode (SD_ST when read)
        self.tick = 0  # the clock the unit has been advanced to
        #: accumulation: running since ``anchor`` with ``acc0`` in the accumulator at that
        #: clock and ``done`` steps emitted since; None: stopped
        self.anchor: int | None = None
        self.acc0 = 0
        self.done = 0
        self.last_step: int | None = None  # clock of the latest step pulse
        self.toggle = 0  # toggle-mode STP level
        self.frozen = False  # nES: steps and counter freeze (§6.13)
        #: while frozen: the start latency left when released (None: nothing to resume)
        self._resume: int | None = None
        self.steps_total = 0  # signed steps ever emitted (for the trace)

    # ------------------------------------------------------------------ registers

    def write(self, name: str, value: int, tick: int) -> None:
        """Take a register value at ``tick``; an unchanged value does nothing."""
        self.advance(tick)
        if name == "SD_SR":
            sr = _signed32(value)
            if sr == self.sr:
                return
            self.sr = sr
            self._restart(tick)  # a new constant clears the accumulator (§6.8.1)
        elif name == "SD_ST":
            st = value & 0xFFFFFFFF
            if st == self.st:
                return
            self.st = st
            self.remaining = st
            if self.anchor is None or not st:
                self._restart(tick)
        elif name == "SD_SL":
            self.sl = value & 0xFFFF
        elif name == "SD_DLY":
            self.dly = value & 0xFFFF
        elif name == "SD_CFG":
            value &= 0x3F
            old, self.cfg = self.cfg, value
            if value & CFG_CLEAR_COUNT:
                self.sc = 0
            rising = value & CFG_ENABLE and not old & CFG_ENABLE
            mode = (old ^ value) & CFG_CONTINUOUS
            if rising or (mode and value & CFG_ENABLE):
                self.remaining = self.st
                self._restart(tick)
            elif not value & CFG_ENABLE:
                self.anchor = None
        else:
            raise KeyError(name)

    @property
    def continuous(self) -> bool:
        return bool(self.cfg & CFG_CONTINUOUS)

    def _restart(self, tick: int) -> None:
        """Clear the accumulator and start after the start latency if the unit may step."""
        may = self.cfg & CFG_ENABLE and self.sr != 0 and (self.continuous or self.remaining > 0)
        self.done = 0
        self.acc0 = 0
        if not may:
            self.anchor = None
            return
        delay = self.dly + START_LATENCY
        if self.frozen:
            self.anchor = None
            self._resume = delay
        else:
            self.anchor = tick + delay

    # ------------------------------------------------------------------ time

    def step_time(self, n: int) -> int | None:
        """The clock of the n-th step after the current anchor (n >= 1), or None."""
        if self.anchor is None or self.sr == 0:
            return None
        return self.anchor + ceil_div((n << 32) - self.acc0, abs(self.sr))

    def next_step(self) -> int | None:
        """The clock of the next step pulse, or None if none will come."""
        return self.step_time(self.done + 1)

    def advance(self, tick: int) -> StepEvent:
        """Run to ``tick`` (inclusive): emit the steps due, count them, stop at the target."""
        ev = StepEvent()
        if tick <= self.tick:
            return ev
        self.tick = tick
        a = self.anchor
        if a is None or tick < a:
            return ev
        c = abs(self.sr)
        total = (self.acc0 + c * (tick - a)) >> 32
        new = total - self.done
        if not self.continuous:
            new = min(new, self.remaining)
        if new <= 0:
            return ev
        self.done += new
        self.last_step = a + ceil_div((self.done << 32) - self.acc0, c)
        self.toggle ^= new & 1
        sign = -1 if self.sr < 0 else 1
        ev.steps = sign * new
        self.steps_total += ev.steps
        if not self.cfg & CFG_CLEAR_COUNT:
            self.sc = (self.sc + ev.steps) & 0xFFFFFFFF
        if not self.continuous:
            self.remaining -= new
            if self.remaining == 0:
                ev.target_reached_at = self.last_step  # IRQ_TARGET_REACHED (§6.8.7)
                self.anchor = None
        return ev

    def freeze(self, on: bool, tick: int) -> None:
        """nES: the step output and the step counter freeze; released, accumulation goes
        on where it stopped. Ref: TMC8460 §6.13."""
        if on == self.frozen:
            return
        self.advance(tick)
        if on:
            a = self.anchor
            self._resume = None
            if a is not None:
                if tick >= a:
                    self.acc0 = self.acc0 + abs(self.sr) * (tick - a) - (self.done << 32)
                    self.done = 0
                    self._resume = 0
                else:
                    self._resume = a - tick
            self.frozen = True
            self.anchor = None
        else:
            self.frozen = False
            if self._resume is not None:
                self.anchor = tick + self._resume
                self._resume = None

    # ------------------------------------------------------------------ pins

    def dir_level(self) -> int:
        """DIR pin: 1 for a negative SD_SR, XOR the polarity bit. Ref: Table 145 (DIR)."""
        d = 1 if self.sr < 0 else 0
        return d ^ (1 if self.cfg & CFG_DIR_POL else 0)

    def stp_level(self, tick: int) -> int:
        """STP pin at ``tick`` (after advance): a pulse of SD_SL + 1 clocks per step, or
        the toggle level; XOR the polarity bit. Ref: Table 145 (t_STEP_PULSE), SD_CFG."""
        if self.cfg & CFG_TOGGLE:
            lvl = self.toggle
        else:
            s = self.last_step
            lvl = 1 if s is not None and s <= tick < s + self.sl + 1 else 0
        return lvl ^ (1 if self.cfg & CFG_STEP_POL else 0)

    def st_readback(self) -> int:
        """SD_ST when read: the steps still to be made. Ref: TMC8460 §6.8.3."""
        return self.remaining & 0xFFFFFFFF
