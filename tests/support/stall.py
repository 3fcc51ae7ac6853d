"""The host-stall watch of the bench (ecatsim/bench/stallwatch.py, decision B8) for timing
tests: a run the host stopped may be repeated instead of blaming master or daemon."""

from __future__ import annotations

from ecatsim.bench.stallwatch import StallWatch

__all__ = ["REPEAT_PAUSE_S", "StallWatch", "spoiled", "stalled"]

#: the wait before a timing test repeats a run the host spoiled: its stalls and steal time
#: come in bursts of seconds (decision K7)
REPEAT_PAUSE_S = 2.0


def stalled(worst_s: float, threshold_s: float = 0.05) -> bool:
    """A stall long enough to explain a master's missed reply or an expired SM watchdog."""
    return worst_s >= threshold_s


def spoiled(steal_s: float, late: int, explained: int) -> bool:
    """A timing run the host spoiled, to be repeated, never passed (decision K7): it has
    ``late`` replies past the master's timeout (a request never answered counts too), and
    the hypervisor took CPU time from the VM during it (``steal_s`` seconds of steal time,
    too coarse to place against one reply) or a stall or a slow spot of the watch
    overlapped each of them (``explained``). A run that failed with no late reply failed
    for another reason than the host."""
    return late > 0 and (steal_s > 0.0 or explained == late)
