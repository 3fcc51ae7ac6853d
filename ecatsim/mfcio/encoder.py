"""The incremental ABN encoder unit: quadrature decoding into a 32.16 accumulator scaled by
ENC_CONST, the N event detector, ENC_LATCH and ENC_STATUS.

Ref: TMC8460 §6.6 Tables 137-139, §6.6.3-§6.6.8; decisions M9-M11.
"""

from __future__ import annotations

# ENC_MODE bits. Ref: TMC8460 §6.6.2 Table 138.
POL_A = 0x0001
POL_B = 0x0002
POL_N = 0x0004
IGNORE_AB = 0x0008
CLR_CONT = 0x0010
CLR_ONCE = 0x0020
POS_EDGE = 0x0040
NEG_EDGE = 0x0080
CLR_ENC_X = 0x0100
SEL_DECIMAL = 0x0400
CLEAR_STATUS = 0x8000

#: quadrature phase of (A, B): one count per step through 0-1-2-3 (Gray code)
PHASE = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}
AB_OF = ((0, 0), (1, 0), (1, 1), (0, 1))
X_MOD = 1 << 32


def const_value(const: int, decimal: bool) -> tuple[int, int]:
    """ENC_CONST as (numerator, denominator): signed 16-bit integer part plus the fraction
    in 1/65536 (binary) or 1/10000 (decimal). Ref: TMC8460 §6.6.7; decision M9."""
    ci = (const >> 16) & 0xFFFF
    if ci & 0x8000:
        ci -= 0x10000
    cf = const & 0xFFFF
    den = 10000 if decimal else 65536
    return ci * den + cf, den


class Encoder:
    """The encoder unit. Inputs come as quadrature transitions (:meth:`inputs`) or, for a
    run of transitions in one direction with N unchanged, :meth:`run`."""

    def __init__(self) -> None:
        self.mode = 0
        self.const = 0
        self.x_w = 0  # ENC_X (W) as last written
        #: accumulator: ``acc`` / ``den`` counts, integer part = ENC_X (48-bit fixed point)
        self.acc = 0
        self.den = 65536
        self.latch = 0
        self.status = 0
        self.a = 0
        self.b = 0
        self.n = 0
        self.armed_once = True  # clr_once: the next event passes (until one did)
        self.events = 0  # N events since the IRQ unit last looked
        self.errors = 0  # transitions of both A and B at once (not counted)

    # ------------------------------------------------------------------ registers

    @property
    def x(self) -> int:
        """ENC_X (R): the integer part of the accumulator, 32 bit. Ref: §6.6.6."""
        return (self.acc // self.den) % X_MOD

    def write(self, name: str, value: int) -> None:
        """Take a register value; an unchanged value does nothing (decision M2)."""
        if name == "ENC_MODE":
            value &= 0x85FF
            if value == self.mode:
                return
            old, self.mode = self.mode, value
            if value & CLEAR_STATUS:
                self.status = 0  # §6.6.4: cleared by writing bit 15 = 1
            if (old ^ value) & SEL_DECIMAL:
                self._rescale(10000 if value & SEL_DECIMAL else 65536)
            self.armed_once = True
            self._level_event()
        elif name == "ENC_X_W":
            value &= 0xFFFFFFFF
            if value == self.x_w:
                return
            self.x_w = value
            self.acc = value * self.den  # loads the accumulator, fraction 0 (§6.6.5)
        elif name == "ENC_CONST":
            self.const = value & 0xFFFFFFFF
        else:
            raise KeyError(name)

    def _rescale(self, den: int) -> None:
        whole, frac = divmod(self.acc, self.den)
        self.acc = whole * den + frac * den // self.den
        self.den = den

    # ------------------------------------------------------------------ inputs

    def _n_active(self) -> bool:
        return self.n == (1 if self.mode & POL_N else 0)

    def _ab_ok(self) -> bool:
        if self.mode & IGNORE_AB:
            return True
        return self.a == (self.mode & POL_A) and self.b == (1 if self.mode & POL_B else 0)

    def _event(self) -> None:
        """An N event candidate: gated by A/B, passed by clr_cont or once by clr_once;
        ENC_X goes to ENC_LATCH, ENC_STATUS is set, ENC_X cleared with clr_enc_x.
        Ref: TMC8460 §6.6.3."""
        m = self.mode
        if not self._ab_ok():
            return
        if not m & CLR_CONT:
            if not (m & CLR_ONCE and self.armed_once):
                return
            self.armed_once = False
        self.latch = self.x
        self.status = 1
        self.events += 1
        if m & CLR_ENC_X:
            self.acc = 0

    def _level_event(self) -> None:
        """Without pos_edge/neg_edge the whole active N signal is the event: while it lasts,
        every clock latches (and clears) again."""
        if not self.mode & (POS_EDGE | NEG_EDGE) and self._n_active():
            self._event()

    def _count(self, k: int) -> None:
        num, den = const_value(self.const, bool(self.mode & SEL_DECIMAL))
        if den != self.den:
            self._rescale(den)
        self.acc = (self.acc + k * num) % (X_MOD * den)

    def inputs(self, a: int, b: int, n: int) -> None:
        """New levels of A, B and N: decode the quadrature step (+1, -1; both changed: not
        counted, decision M10), then the N event detector. Ref: TMC8460 §6.6.1, §6.6.3."""
        was = self._n_active()
        d = (PHASE[(a, b)] - PHASE[(self.a, self.b)]) % 4
        self.a, self.b, self.n = a, b, n
        if d == 1:
            self._count(1)
        elif d == 3:
            self._count(-1)
        elif d == 2:
            self.errors += 1
        now = self._n_active()
        m = self.mode
        if now and not was and m & POS_EDGE:
            self._event()
        if was and not now and m & NEG_EDGE:
            self._event()
        if not m & (POS_EDGE | NEG_EDGE) and now:
            self._event()

    def run(self, k: int, n: int) -> None:
        """``|k|`` quadrature transitions in the direction of ``k`` with N at level ``n``
        throughout (it may change with the first transition). Equal to ``|k|`` calls of
        :meth:`inputs`, in O(1) unless N events happen on the way."""
        if k == 0:
            return
        step = 1 if k > 0 else -1
        if self.n != n:
            ph = (PHASE[(self.a, self.b)] + step) % 4
            self.inputs(*AB_OF[ph], n)  # N changes with the first transition
            self.run(k - step, n)
            return
        p0 = PHASE[(self.a, self.b)]
        m = self.mode
        level = not m & (POS_EDGE | NEG_EDGE) and self._n_active()
        passes = m & CLR_CONT or (m & CLR_ONCE and self.armed_once)
        if not (level and passes):
            self._count(k)
            self.a, self.b = AB_OF[(p0 + k) % 4]
            return
        # a level event at every transition whose A/B match (every one with ignore_AB)
        steps = abs(k)
        if m & IGNORE_AB:
            first, period = 1, 1
        else:
            want = PHASE[(m & POL_A, 1 if m & POL_B else 0)]
            first = (step * (want - p0)) % 4 or 4
            period = 4
        if first > steps:
            self._count(k)
            self.a, self.b = AB_OF[(p0 + k) % 4]
            return
        last = first + (steps - first) // period * period
        if not m & CLR_CONT:  # clr_once: the first match only
            last = first
        self._count(step * first)
        self.a, self.b = AB_OF[(p0 + step * first) % 4]
        self._event()
        if last > first:
            if m & CLR_ENC_X:  # cleared at every match: what one period adds
                self.acc = 0
                self._count(step * period)
            else:
                self._count(step * (last - first))
            self.a, self.b = AB_OF[(p0 + step * last) % 4]
            self.events += (last - first) // period - 1
            self._event()
        self._count(step * (steps - last))
        self.a, self.b = AB_OF[(p0 + step * steps) % 4]
