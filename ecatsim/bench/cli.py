"""``ecatsim bench``: the command and its options (root; pysoem, the bench extra).

It builds a C echo (the floor), runs a pysoem master in one network namespace against the
daemon in another, and writes a table and <results>/bench-<time>.json; with ``--bringup``
it times every frame of a bring-up instead. See docs/performance.md "How to measure".
"""

from __future__ import annotations

import os
from pathlib import Path

import click

from ecatsim.bench.options import BenchOptions
from ecatsim.bench.results import DEFAULT_DIR
from ecatsim.errors import UserError

#: the one line ``ecatsim bench`` gives where pysoem is not installed
NO_PYSOEM = "ecatsim bench needs pysoem: pip install 'ecatsim[bench]'"


@click.command("bench")
@click.option(
    "--slaves",
    multiple=True,
    type=int,
    default=(1, 4, 16, 64),
    show_default=True,
    help="Segment sizes to measure (repeat the option: --slaves 1 --slaves 16).",
)
@click.option(
    "--seconds",
    type=float,
    default=5.0,
    show_default=True,
    help="Cyclic exchange per run, against the daemon and against the floor.",
)
@click.option(
    "--period-us",
    type=int,
    default=1000,
    show_default=True,
    help="The master's cycle time (SYNC0 runs at the same period).",
)
@click.option(
    "--modes",
    multiple=True,
    type=click.Choice(["blocking", "busy-poll"]),
    default=("blocking",),
    show_default=True,
    help="The daemon's wake-up modes to measure.",
)
@click.option(
    "--placements",
    multiple=True,
    type=click.Choice(["unpinned", "same-cpu"]),
    default=("unpinned", "same-cpu"),
    show_default=True,
    help="unpinned: the scheduler places master and daemon; same-cpu: both on --cpu (0).",
)
@click.option("--cpu", type=int, help="Pin the daemon (and the floor) to this CPU.")
@click.option(
    "--rt-priority",
    type=int,
    help="The daemon's SCHED_FIFO priority (default: the daemon's own default).",
)
@click.option("--no-rt", is_flag=True, help="Run the daemon with --no-rt (the ordinary scheduler).")
@click.option(
    "--no-follow-master-cpu",
    is_flag=True,
    help="Run the daemon with --no-follow-master-cpu (it stays where the scheduler puts it).",
)
@click.option(
    "--no-hold-cpu-latency",
    is_flag=True,
    help="Run the daemon with --no-hold-cpu-latency (the CPUs may enter their idle states).",
)
@click.option(
    "--master-spin", is_flag=True, help="The master spins between cycles instead of sleeping."
)
@click.option(
    "--max-rate", is_flag=True, help="Also search the highest cycle rate held with 0 lost frames."
)
@click.option(
    "--hold",
    type=float,
    default=60.0,
    show_default=True,
    help="Seconds a rate must hold in --max-rate.",
)
@click.option(
    "--rates",
    multiple=True,
    type=int,
    default=(8000, 4000, 2000, 1000, 500),
    show_default=True,
    help="Rates in Hz that --max-rate tries, highest first.",
)
@click.option(
    "--hold-floor",
    is_flag=True,
    help="Hold each rate against the C floor too (is 0 lost possible here?).",
)
@click.option(
    "--repeat",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Measure each segment size this many times, each with its own daemon and floor, "
    "and print the median of the ratios (the machine's drift between runs moves a single "
    "run's ratio by up to 2x).",
)
@click.option(
    "--bringup",
    multiple=True,
    type=click.IntRange(min=1),
    help="Instead of the round trips: bring N drives to OP with DC and run --cycles cycles, "
    "every reply timed by a capture on the master's end (repeat the option for more sizes).",
)
@click.option(
    "--cycles",
    type=click.IntRange(min=1),
    default=2000,
    show_default=True,
    help="Cycles at --period-us after the bring-up of --bringup.",
)
@click.option(
    "--overlap",
    is_flag=True,
    help="--bringup: the master maps the process data overlapped (config_overlap_map), so "
    "its IO map holds more drives.",
)
@click.option(
    "--master-rt",
    type=click.IntRange(min=1, max=99),
    help="--bringup: run the master SCHED_FIFO at this priority, as real-time masters run "
    "(above the daemon's 20).",
)
@click.option(
    "--master-cpu",
    type=int,
    help="--bringup: pin the master to this CPU (with --cpu for the daemon: a core each).",
)
@click.option(
    "--master",
    type=click.Choice(["pysoem", "soem"]),
    default="pysoem",
    show_default=True,
    help="--bringup's master: pysoem (up to 199 slaves, a 4096-byte IO map, SYNC0, drives "
    "enabled and moving) or soem: SOEM's own DC sample red_test built from pysoem's sdist "
    "with 1023 slaves and a 64 KiB IO map (SYNC0 with --sync0, drives enabled holding "
    "their positions; needs 'cc').",
)
@click.option(
    "--chain",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="--bringup: the drives in this many chained daemons, one segment to the master "
    "(each next daemon behind the previous one's --out-iface), daemon k pinned to CPU k "
    "modulo the CPUs.",
)
@click.option(
    "--restart",
    is_flag=True,
    help="--bringup (pysoem): a first master brings the drives to OP, runs 200 cycles and "
    "closes; the timed bring-up is a second master's against the running segment, as a "
    "master restarted in a test meets it (broadcasts over configured slaves).",
)
@click.option(
    "--sync0",
    is_flag=True,
    help="--master soem: start every slave's SYNC0 at --period-us (SOEM's ec_dcsync0 added "
    "after red_test's ec_configdc; red_test itself starts none).",
)
@click.option(
    "--results",
    type=click.Path(file_okay=False, path_type=Path),
    default=DEFAULT_DIR,
    show_default=True,
    help="Directory the run's JSON is written to (relative to the current directory).",
)
def bench(**kw: object) -> None:
    """Measure the daemon against a real master and a C echo floor. Root.

    \b
    Per run it prints the master's round trip (median, p99), the floor's, their ratio,
    lost frames and WKC errors, the daemon's CPU, and the daemon's own reply time (median,
    p99.99, max) from kernel timestamps on both ends of the link. With --bringup: the
    reply times of every frame of a bring-up and the cycles after it (p50, p99.9, max,
    over 1 ms and 2 ms, resends, unanswered, the slowest frames) and the cycles' WKC.
    """
    opts = BenchOptions(**kw)  # type: ignore[arg-type]
    if opts.master == "soem" and not opts.bringup:
        raise UserError("--master soem is the master of --bringup N: add --bringup N")
    if opts.restart and (opts.master != "pysoem" or not opts.bringup):
        raise UserError("--restart is for --bringup N with the pysoem master")
    if opts.sync0 and opts.master != "soem":
        raise UserError("--sync0 is for --master soem (the pysoem master starts SYNC0 itself)")
    try:
        import pysoem  # noqa: F401
    except ImportError:
        raise UserError(NO_PYSOEM) from None
    if os.geteuid() != 0:
        raise UserError("ecatsim bench needs root (network namespaces, raw sockets): use sudo")
    if opts.bringup:
        from ecatsim.bench import bringup

        raise SystemExit(bringup.run(opts))
    from ecatsim.bench import roundtrip

    raise SystemExit(roundtrip.run(opts))
