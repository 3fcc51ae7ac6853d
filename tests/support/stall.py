"""The host-stall watch of the bench (ecatsim/bench/stallwatch.py, decision B8) for timing
tests: a run the host stopped may be repeated instead of blaming master or daemon."""

from __future__ import annotations

from ecatsim.bench.stallwatch import StallWatch

__all__ = ["StallWatch", "stalled"]


def stalled(worst_s: float, threshold_s: float = 0.05) -> bool:
    """A stall long enough to explain a master's missed reply or an expired SM watchdog."""
    return worst_s >= threshold_s
