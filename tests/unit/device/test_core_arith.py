"""The compiled core's C replacements for round() and math.floor (drive._round,
servo._floor) give the builtins' results, ties and limits included (decision P5)."""

from __future__ import annotations

import math

import pytest

from ecatsim.device import drive, servo
from tests.support.core import source_twin

VALUES = [
    0.0,
    -0.0,
    0.5,
    1.5,
    2.5,
    -0.5,
    -1.5,
    -2.5,
    0.49999999999999994,
    -0.49999999999999994,
    2.4999999999999996,
    1e-300,
    -1e-300,
    123456.5,
    -123456.5,
    4503599627370495.5,
    -4503599627370495.5,
    2.0**52 + 1,
    2.0**53,
    -(2.0**53),
    3.9e18,
    -3.9e18,
    4.0e18,
    1e19,
    -1e300,
    1e300,
    2**31 - 0.5,
    -(2**31) - 0.5,
    7.000000000000001,
    -6.999999999999999,
]


@pytest.mark.parametrize("x", VALUES)
def test_round_is_builtin_round(x: float) -> None:
    got = source_twin(drive)._round(x)
    assert type(got) is int and got == round(x)


@pytest.mark.parametrize("x", VALUES)
def test_floor_is_math_floor(x: float) -> None:
    assert source_twin(servo)._floor(x) == math.floor(x)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nan_and_infinities_raise_as_the_builtins(bad: float) -> None:
    with pytest.raises((ValueError, OverflowError)) as want:
        round(bad)
    with pytest.raises(want.type):
        source_twin(drive)._round(bad)
    with pytest.raises(want.type):
        source_twin(servo)._floor(bad)
