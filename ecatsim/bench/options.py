"""What one ``ecatsim bench`` run measures (the command's options, :mod:`ecatsim.bench.cli`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ecatsim.bench.results import DEFAULT_DIR


@dataclass(frozen=True, slots=True)
class BenchOptions:
    """What one benchmark run measures."""

    slaves: tuple[int, ...]
    seconds: float
    period_us: int
    modes: tuple[str, ...]
    placements: tuple[str, ...]
    cpu: int | None
    rt_priority: int | None
    no_rt: bool
    no_follow_master_cpu: bool
    master_spin: bool
    max_rate: bool
    hold: float
    rates: tuple[int, ...]
    hold_floor: bool
    repeat: int
    bringup: tuple[int, ...] = ()
    cycles: int = 2000
    overlap: bool = False
    #: the master's SCHED_FIFO priority and CPU (--bringup; None: ordinary, unpinned)
    master_rt: int | None = None
    master_cpu: int | None = None
    #: --bringup's master: "pysoem" or "soem" (SOEM's red_test, :mod:`ecatsim.bench.redtest`)
    master: str = "pysoem"
    #: --master soem: start SYNC0 on every slave (SOEM's ec_dcsync0 added after ec_configdc)
    sync0: bool = False
    #: --bringup: the drives in this many chained daemons (each on its own CPU)
    chain: int = 1
    #: --bringup (pysoem): time a second master's bring-up against the running segment
    restart: bool = False
    results: Path = DEFAULT_DIR
    #: --no-hold-cpu-latency for the daemon (decision K12)
    no_hold_cpu_latency: bool = False

    def scheduling_flags(self) -> tuple[str, ...]:
        """The daemon's scheduling options: ``--no-rt`` or ``--rt-priority N``, and
        ``--no-follow-master-cpu`` and ``--no-hold-cpu-latency`` (its CPU is the
        placement's, added by the caller)."""
        flags: tuple[str, ...] = ()
        if self.no_rt:
            flags = ("--no-rt",)
        elif self.rt_priority:
            flags = ("--rt-priority", str(self.rt_priority))
        if self.no_follow_master_cpu:
            flags = (*flags, "--no-follow-master-cpu")
        if self.no_hold_cpu_latency:
            flags = (*flags, "--no-hold-cpu-latency")
        return flags
