"""Golden tests of the MFCIO PWM unit against TMC8460 §6.9: t_PWM = (1 + PWM_MAXCNT) clocks
of 100 MHz (Table 148), duty PWM_VALUE / (1 + PWM_MAXCNT) left, right and centre aligned
(Figures 36-38), counter shift (Figure 40), chopper modes (Table 149), brake-before-make
gaps (Figure 41), trigger pulses, polarities and the emergency off-state (§6.9.13)."""

from __future__ import annotations

import pytest

from ecatsim.mfcio.pwm import ALIGN_CENTER, ALIGN_LEFT, ALIGN_OFF, ALIGN_RIGHT, Pwm
from ecatsim.mfcio.timebase import F_PWM_CLK_HZ, PWM_TICK_NS

PERIOD = 4000  # MAXCNT 3999: 40 us, 25 kHz
Interval = tuple[int, int]


def unit(align: int, value: int, **regs: int) -> Pwm:
    p = Pwm()
    p.write("PWM_MAXCNT", PERIOD - 1, 0)
    p.write("PWM_ALIGNMENT", align, 0)
    p.write("PWM_CHOPMODE", 0x0666, 0)  # high-side chopper on all three channels
    for ch in range(3):
        p.write(f"PWM_VALUE_{ch}", value, 0)
    for k, v in regs.items():
        p.write(k, v, 0)
    return p


def on_interval(p: Pwm, ch: int = 0, side: str = "hs") -> list[tuple[int, int]]:
    """[start, end) counter ranges where the side is on during one cycle."""
    out: list[tuple[int, int]] = []
    start = None
    for c in range(PERIOD + 1):
        lvl = getattr(p.outputs(c % PERIOD), side)[ch] if c < PERIOD else 0
        if lvl and start is None:
            start = c
        elif not lvl and start is not None:
            out.append((start, c))
            start = None
    return out


def test_period_at_maximum_resolution() -> None:
    """Table 148: MAXCNT 4095: t_PWM = 4096 x 10 ns = 40.96 us, f_PWM 24.414 kHz."""
    p = Pwm()
    p.write("PWM_MAXCNT", 4095, 0)
    assert p.period * PWM_TICK_NS == 40_960
    assert round(F_PWM_CLK_HZ / p.period) == 24_414
    p.write("PWM_MAXCNT", 0xFFFF, 0)  # 12 bits implemented
    assert p.period == 4096


@pytest.mark.parametrize(
    ("align", "interval"),
    [(ALIGN_LEFT, (0, 1000)), (ALIGN_RIGHT, (3000, 4000)), (ALIGN_CENTER, (1500, 2500))],
)
def test_duty_and_position_per_alignment(align: int, interval: tuple[int, int]) -> None:
    p = unit(align, 1000)
    assert on_interval(p) == [interval]
    assert p.duty(0) == (1000, 4000)  # 25 %


def test_alignment_off_switches_everything_off() -> None:
    p = unit(ALIGN_OFF, 1000)
    assert on_interval(p) == []
    assert p.duty(0) == (0, 4000)


def test_counter_shift_moves_the_pulse_not_the_duty() -> None:
    """Figure 40: a channel shifted from the centre keeps its on-time."""
    p = unit(ALIGN_CENTER, 1000, PWM_CNTRSHIFT_2=300)
    assert on_interval(p, 2) == [(1800, 2800)]
    assert on_interval(p, 0) == [(1500, 2500)]
    q = unit(ALIGN_LEFT, 1000, PWM_CNTRSHIFT_0=3500)  # wraps around the cycle end
    assert on_interval(q, 0) == [(0, 500), (3500, 4000)]


def test_complementary_chopper_brake_before_make() -> None:
    """%111: the high side comes on BBM_H clocks after the low side went off, the low side
    BBM_L clocks after the high side went off (Figure 41): gaps of 100 ns and 200 ns."""
    p = unit(ALIGN_LEFT, 1000, PWM_CHOPMODE=0x0007, PWM_BBM_H=10, PWM_BBM_L=20)
    assert on_interval(p, 0, "hs") == [(10, 1000)]
    assert on_interval(p, 0, "ls") == [(1020, 4000)]
    gap_h = 10 * PWM_TICK_NS
    gap_l = 20 * PWM_TICK_NS
    assert (gap_h, gap_l) == (100, 200)


@pytest.mark.parametrize(
    ("mode", "hs", "ls"),
    [(0b000, [], []), (0b001, [], [(0, 4000)]), (0b010, [(0, 4000)], []), (0b011, [], [])],
)
def test_static_chopper_modes(
    mode: int, hs: list[tuple[int, int]], ls: list[tuple[int, int]]
) -> None:
    p = unit(ALIGN_LEFT, 1000, PWM_CHOPMODE=mode)
    assert on_interval(p, 0, "hs") == hs
    assert on_interval(p, 0, "ls") == ls


def test_low_side_chopper() -> None:
    p = unit(ALIGN_LEFT, 1000, PWM_CHOPMODE=0b101)
    assert on_interval(p, 0, "ls") == [(0, 1000)]
    assert on_interval(p, 0, "hs") == []


def test_trigger_pulses_and_their_length() -> None:
    """PULSE_ZERO at the cycle start, PULSE_CENTER at the middle, PULSE_A/B where set,
    PULSE_AB their OR, each PULSE_LENGTH clocks long (t = PULSE_LENGTH * 10 ns)."""
    p = unit(ALIGN_CENTER, 1000, PWM_PULSE_A=100, PWM_PULSE_B=3000, PWM_PULSE_LENGTH=5)
    lv = {c: p.outputs(c) for c in (0, 4, 5, 100, 104, 105, 2000, 2004, 2005, 3000)}
    assert [lv[c].zero for c in (0, 4, 5)] == [1, 1, 0]
    assert [lv[c].a for c in (100, 104, 105)] == [1, 1, 0]
    assert [lv[c].center for c in (2000, 2004, 2005)] == [1, 1, 0]
    assert [lv[c].b for c in (3000, 100)] == [1, 0]
    assert [lv[c].ab for c in (100, 3000, 2000)] == [1, 1, 0]


def test_polarities_invert_each_group() -> None:
    p = unit(ALIGN_LEFT, 1000, PWM_CHOPMODE=0x0007, PWM_POLARITIES=0x7F)
    o = p.outputs(500)  # high side on, low side off
    assert (o.hs[0], o.ls[0]) == (0, 1)
    assert (o.zero, o.a, o.b, o.center, o.ab) == (1, 1, 1, 1, 1)


def test_emergency_switch_off_state_follows_polarities() -> None:
    """§6.9.13: nES brings both sides to the off-state; POL(0) = 0: off = 0; POL(1) = 1:
    off = 1."""
    p = unit(ALIGN_LEFT, 1000, PWM_CHOPMODE=0x0007, PWM_POLARITIES=0x02)
    p.emergency = True
    for c in (0, 500, 2000):
        o = p.outputs(c)
        assert (o.hs, o.ls) == ([1, 1, 1], [0, 0, 0])


def test_new_maxcnt_starts_a_new_cycle() -> None:
    p = unit(ALIGN_LEFT, 100)
    p.write("PWM_MAXCNT", 999, 12_345)
    assert p.counter(12_345) == 0
    assert p.next_start(12_345) == 13_345
    assert p.marks_between(12_345, 13_345) == {1, 2, 3, 4}
