"""Golden tests of the MFCIO step/direction unit against TMC8460 §6.8 Table 145:
f_STEP = f_CLK / 2^32 * SR, t_STEP1st = 2^32/SR + (SD_DLY + 1) + 2 clocks, t_STEP_PULSE =
(SD_SL + 1) clocks, DIR from the sign of SR, n pulses or continuous, target reached."""

from __future__ import annotations

import itertools

import pytest

from ecatsim.mfcio.stepdir import (
    CFG_CLEAR_COUNT,
    CFG_CONTINUOUS,
    CFG_DIR_POL,
    CFG_ENABLE,
    CFG_STEP_POL,
    CFG_TOGGLE,
    StepDir,
    f_step_mhz,
    sr_for,
)

T0 = 1000  # the clock of the writes


def unit(sr: int, *, cfg: int = CFG_ENABLE | CFG_CONTINUOUS, st: int = 0, dly: int = 0) -> StepDir:
    s = StepDir()
    s.advance(T0)
    s.write("SD_DLY", dly, T0)
    s.write("SD_ST", st, T0)
    s.write("SD_SR", sr & 0xFFFFFFFF, T0)
    s.write("SD_CFG", cfg, T0)
    return s


def step_clocks(s: StepDir, until: int) -> list[int]:
    """The clocks at which steps come, found clock by clock."""
    out = []
    for t in range(s.tick + 1, until + 1):
        if s.advance(t).steps:
            out.append(t)
    return out


def test_accumulation_constant_for_10_khz() -> None:
    # SR = int(2^32 * 10000 / 25e6) = int(1717986.9184)
    assert sr_for(10_000) == 1_717_986
    assert sr_for(-10_000) == -1_717_986
    # f_STEP = 25 MHz / 2^32 * 1717986 = 9999.9946... Hz
    assert round(f_step_mhz(1_717_986)) == 9_999_995


def test_maximum_step_frequency_is_half_the_clock() -> None:
    """Table 145: max f_STEP 12.5 MHz: SR = 2^31 steps every 2 clocks."""
    s = unit(1 << 31)
    assert f_step_mhz(1 << 31) == 12_500_000_000
    clocks = step_clocks(s, T0 + 20)
    assert clocks[0] == T0 + 2 + 3
    assert [b - a for a, b in itertools.pairwise(clocks)] == [2] * (len(clocks) - 1)


@pytest.mark.parametrize(("dly", "first"), [(0, 7), (1, 8), (10, 17), (1000, 1007)])
def test_time_to_first_step(dly: int, first: int) -> None:
    """t_STEP1st = 2^32/SR * t_CLK + (SD_DLY + 1) * t_CLK + 2 * t_CLK; SR = 2^30: 4 + 1 + 2."""
    s = unit(1 << 30, dly=dly)
    clocks = step_clocks(s, T0 + first + 8)
    assert clocks[:3] == [T0 + first, T0 + first + 4, T0 + first + 8]


def test_fractional_step_period_alternates_between_neighbours() -> None:
    """SR for 10 kHz: 2^32/SR = 2500.0013 clocks: step n at ceil(n * 2^32 / SR) + 3."""
    s = unit(1_717_986)
    clocks = step_clocks(s, T0 + 5 * 2501 + 3)
    assert clocks == [T0 + 3 + -(-(n << 32) // 1_717_986) for n in range(1, 6)]
    assert clocks[0] == T0 + 2501 + 3


def test_n_pulses_stop_at_the_target_with_the_irq() -> None:
    s = unit(1_717_986, cfg=CFG_ENABLE, st=2000)
    ev = s.advance(T0 + 10_000_000)
    assert ev.steps == 2000
    assert s.sc == 2000
    assert s.remaining == 0
    last = T0 + 3 + -(-(2000 << 32) // 1_717_986)
    assert ev.target_reached_at == last == s.last_step
    assert s.advance(T0 + 20_000_000).steps == 0
    assert s.sc == 2000


def test_pulse_length_is_sl_plus_one_clocks() -> None:
    """t_STEP_PULSE = (SD_SL + 1) / f_CLK; the polarity bit inverts the pin."""
    s = unit(1 << 20)  # 4096 clocks between steps
    s.write("SD_SL", 24, T0)
    first = T0 + 4096 + 3
    s.advance(first)
    assert [s.stp_level(t) for t in (first - 1, first, first + 24, first + 25)] == [0, 1, 1, 0]
    s.write("SD_CFG", CFG_ENABLE | CFG_CONTINUOUS | CFG_STEP_POL, first)
    assert [s.stp_level(t) for t in (first, first + 25)] == [0, 1]


def test_negative_constant_sets_dir_and_counts_down() -> None:
    """DIR = 1 for SR < 0 (Table 145); the direction polarity bit inverts the pin."""
    s = unit(-(1 << 30))
    s.advance(T0 + 7 + 4 * 9)
    assert s.sc == (-10) & 0xFFFFFFFF
    assert s.dir_level() == 1
    s.write("SD_CFG", CFG_ENABLE | CFG_CONTINUOUS | CFG_DIR_POL, s.tick)
    assert s.dir_level() == 0
    assert unit(1 << 30).dir_level() == 0


def test_toggle_mode_toggles_per_step() -> None:
    s = unit(1 << 30, cfg=CFG_ENABLE | CFG_CONTINUOUS | CFG_TOGGLE)
    levels = []
    for t in (T0 + 7, T0 + 11, T0 + 15):
        s.advance(t)
        levels.append(s.stp_level(t))
    assert levels == [1, 0, 1]


def test_zero_constant_stops_and_clears_the_accumulator() -> None:
    s = unit(1 << 30)
    s.advance(T0 + 9)  # one step at +7, accumulator half way to the next
    assert s.sc == 1
    s.write("SD_SR", 0, T0 + 9)
    assert s.advance(T0 + 1000).steps == 0
    s.write("SD_SR", 1 << 30, T0 + 1000)  # restarts from an empty accumulator
    assert step_clocks(s, T0 + 1007) == [T0 + 1007]


def test_clear_count_bit_holds_the_counter_at_zero() -> None:
    s = unit(1 << 30)
    s.advance(T0 + 20)
    assert s.sc == 4
    s.write("SD_CFG", CFG_ENABLE | CFG_CONTINUOUS | CFG_CLEAR_COUNT, T0 + 20)
    s.advance(T0 + 40)
    assert s.sc == 0
    s.write("SD_CFG", CFG_ENABLE | CFG_CONTINUOUS, T0 + 40)
    s.advance(T0 + 48)
    assert s.sc == 2


def test_disable_stops_and_enable_restarts_the_move() -> None:
    s = unit(1 << 30, cfg=CFG_ENABLE, st=5)
    s.advance(T0 + 11)
    assert s.sc == 2
    s.write("SD_CFG", 0, T0 + 11)
    assert s.advance(T0 + 100).steps == 0
    s.write("SD_CFG", CFG_ENABLE, T0 + 100)  # a new move of SD_ST steps
    assert s.advance(T0 + 1000).steps == 5
    assert s.sc == 7


def test_rewriting_the_same_values_is_no_new_move() -> None:
    """Decision M2: a shadow copy of an unchanged value is no write."""
    s = unit(1 << 30, cfg=CFG_ENABLE, st=3)
    s.advance(T0 + 100)
    for name, v in (("SD_SR", 1 << 30), ("SD_ST", 3), ("SD_CFG", CFG_ENABLE)):
        s.write(name, v, T0 + 100)
    assert s.advance(T0 + 1000).steps == 0
    s.write("SD_ST", 4, T0 + 1000)  # a new target restarts the stopped unit
    assert s.advance(T0 + 2000).steps == 4


def test_freeze_holds_steps_and_counter() -> None:
    """nES: the S/D unit freezes (§6.13) and goes on where it stopped."""
    s = unit(1 << 30)
    s.advance(T0 + 9)
    s.freeze(True, T0 + 9)
    assert s.advance(T0 + 1000).steps == 0
    s.freeze(False, T0 + 1000)
    # 2 clocks of accumulation were done before the freeze: 2 more to the next step
    assert step_clocks(s, T0 + 1006) == [T0 + 1002, T0 + 1006]
