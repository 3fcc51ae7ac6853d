"""The host-stall watch of the bench (ecatsim/bench/stallwatch.py, decision B8) for timing
tests: a run the host stopped may be repeated instead of blaming master or daemon."""

from __future__ import annotations

from ecatsim.bench.stallwatch import StallWatch

__all__ = ["REPEAT_PAUSE_S", "StallWatch", "stalled"]

#: the wait before a timing test repeats a run the host spoiled: its stalls and steal time
#: come in bursts of seconds (decision K7)
REPEAT_PAUSE_S = 2.0


def stalled(worst_s: float, threshold_s: float = 0.05) -> bool:
    """A stall long enough to explain a master's missed reply or an expired SM watchdog."""
    return worst_s >= threshold_s
