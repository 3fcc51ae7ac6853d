"""``ecatsim bench`` is a click command with help for every option; reply times pair up."""

from __future__ import annotations

import sys
from pathlib import Path

from click.testing import CliRunner

from ecatsim.bench_cli import bench
from ecatsim.cli import cli

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from reply_time import ReplyTimer, percentile


def test_every_option_has_help() -> None:
    missing = [p.name for p in bench.params if not getattr(p, "help", None)]
    assert missing == []
    r = CliRunner().invoke(cli, ["bench", "--help"])
    assert r.exit_code == 0
    assert r.output.startswith("Usage: cli bench [OPTIONS]")
    assert "p99.99" in r.output


def test_reply_times_pair_requests_and_replies_by_index() -> None:
    rt = ReplyTimer((None, "lo"), (None, "lo"))
    # (stamp ns, is_reply, idx): two requests in flight, one reply lost, one stray reply
    rt.events = [
        (1_000, False, 7),
        (1_500, False, 8),
        (21_000, True, 7),
        (41_500, True, 8),
        (50_000, False, 9),
        (60_000, True, 3),
    ]
    assert rt.reply_us() == ([20.0, 40.0], 2)
    st = rt.stats()
    assert (st["frames"], st["unpaired"], st["median"], st["max"]) == (2, 2, 20.0, 40.0)


def test_percentile_is_nearest_rank() -> None:
    us = [float(i) for i in range(1, 10001)]
    assert (percentile(us, 0.5), percentile(us, 0.9999), percentile(us, 1.0)) == (
        5000.0,
        9999.0,
        10000.0,
    )


def test_repeated_runs_report_the_median_ratio_per_size() -> None:
    from bench import repeated

    def run(n: int, ratio: float, rtt: float) -> dict[str, object]:
        return {"mode": "blocking", "placement": "same-cpu", "slaves": n,
                "ratio_median": ratio, "rtt_us": {"median": rtt},
                "floor_rtt_us": {"median": 10.0}, "cpu_percent": 5.0}  # fmt: skip

    runs = [run(1, 1.9, 19.0), run(1, 1.1, 11.0), run(1, 1.4, 14.0), run(16, 3.0, 30.0)]
    rows = repeated(runs)
    assert [(r["slaves"], r["runs"]) for r in rows] == [(1, 3), (16, 1)]
    one = rows[0]
    assert (one["ratio_median"], one["ratio_min"], one["ratio_max"]) == (1.4, 1.1, 1.9)
    assert (one["rtt_median_us"], one["floor_median_us"]) == (14.0, 10.0)


def test_wkc_mismatches_are_named_with_their_wkc_and_time() -> None:
    from bench import wkc_seen_text

    run = {"expected_wkc": 192, "wkc_error_seen": [(96, 6387), (0, 2100)]}
    assert wkc_seen_text(run) == " wkc seen 96/192 after 6387 us wkc seen 0/192 after 2100 us"
    assert wkc_seen_text({"expected_wkc": 3, "wkc_error_seen": []}) == ""
