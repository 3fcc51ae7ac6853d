"""The host probe's analysis (ecatsim/bench/steadiness.py): windows' speeds from counts.

Ref: docs/decisions.md B7.
"""

from __future__ import annotations

import pytest

from ecatsim.bench.steadiness import analyse, parse, text


def test_a_window_s_speed_is_its_count_against_the_unhindered_rate() -> None:
    # 1000 ns a repetition, 10 ms windows: 10 000 repetitions is full speed
    counts = [10_000, 9_000, 5_900, 2_000, 10_100, 6_000, 2_999, 8_000, 10_000, 10_000]
    assert analyse(1000, 10_000_000, counts) == {
        "windows": 10,
        "slowed_pct": 30.0,  # 0.59, 0.2, 0.2999: below 0.6
        "stalled_pct": 20.0,  # 0.2, 0.2999: below 0.3
        "min_speed": 0.2,
        "median_speed": 0.9,  # sorted: ... 0.8, 0.9, 1.0 ...: the sixth of ten
    }


def test_no_windows_or_no_rate_is_no_figure() -> None:
    assert analyse(0, 10_000_000, [5]) == {"windows": 0}
    assert analyse(1000, 10_000_000, []) == {"windows": 0}


def test_the_probe_s_line_is_parsed_and_anything_else_refused() -> None:
    cpu, f = parse("cpu 1 chunk_ns 2000 window_ns 10000000 counts 5000 2500 5000")
    assert cpu == 1
    assert f == {"windows": 3, "slowed_pct": 33.3, "stalled_pct": 0.0, "min_speed": 0.5,
                 "median_speed": 1.0}  # fmt: skip
    with pytest.raises(ValueError, match="unexpected output"):
        parse("sched_setscheduler: Operation not permitted")


def test_the_line_names_every_cpu() -> None:
    host = {"cpus": {1: analyse(1000, 10_000_000, [10_000, 2_000]),
                     0: analyse(1000, 10_000_000, [10_000])}}  # fmt: skip
    assert text(host) == (
        "host steadiness (10 ms windows): cpu0 0.0 % below 60% speed, 0.0 % below 30%, "
        "slowest 1.0; cpu1 50.0 % below 60% speed, 50.0 % below 30%, slowest 0.2"
    )
