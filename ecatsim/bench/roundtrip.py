"""The round-trip benchmark: the daemon against a real master and against a C echo floor,
same run.

For each N it starts the daemon (N TMC8670 drives) in a private network namespace, brings
the segment to OP with pysoem (DC active, SYNC0 every cycle) in another, runs cyclic
exchange kept mid-way between SYNC0 pulses with every drive enabled in csp and moving, and
records the round trip of each send_processdata()/receive_processdata() pair, lost frames,
WKC mismatches, the daemon's CPU time and its own reply time to each frame from kernel
timestamps on both ends of the link (:mod:`ecatsim.bench.capture`). Then the daemon is
frozen and the floor, a minimal C responder compiled here with the system compiler
(:mod:`ecatsim.bench.floor`), answers the same master's same frames in the same wake-up
mode: the ratio of the medians is the figure the targets use. Each run is made unpinned
and with master, daemon and floor pinned to one CPU. A raw LRW frame timed before
bring-up (slaves in INIT) is reported too. Results: a table on stdout and
bench-<time>.json in the results directory. Ref: docs/performance.md "How to measure".
"""

from __future__ import annotations

import os
import platform
import shutil
import signal
import socket
import statistics
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ecatsim.bench import results
from ecatsim.bench.capture import Capture
from ecatsim.bench.floor import build_echo, echo_command
from ecatsim.bench.master import cycles, pysoem_master, stats, wkc_seen_text
from ecatsim.bench.netns import Daemon, NetnsPair, in_netns
from ecatsim.bench.options import BenchOptions
from ecatsim.wire import datagram as dg


def raw_rtt(pair: NetnsPair, frame: bytes, count: int) -> tuple[list[float], int]:
    """Round trips of one raw frame from the master namespace."""
    with in_netns(pair.master_ns):
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
        s.bind((pair.master_if, 0))
    s.settimeout(0.05)
    rtts, lost = [], 0
    try:
        for _ in range(count):
            t = time.perf_counter()
            s.send(frame)
            while True:
                try:
                    r = s.recv(2048)
                except TimeoutError:
                    lost += 1
                    break
                if r[6] & 2:
                    rtts.append(time.perf_counter() - t)
                    break
    finally:
        s.close()
    return rtts, lost


def with_master(
    pair: NetnsPair,
    n: int,
    period_us: int,
    echo: Path | None,
    echo_mode: str,
    seconds: float,
    pin: list[str],
    daemon_pid: int,
    spin: bool,
) -> dict[str, Any]:
    """Cyclic exchange against the daemon, then, with the same pysoem master and frames,
    against the C echo swapped in for the daemon (docs/performance.md "How to measure").
    The round trips of both are taken with nothing else listening on the link; the reply
    times (``reply_us``, ``floor_reply_us``) in a second exchange of each, under the taps
    of :meth:`Capture.both_ends`, whose thread wakes with every frame in the master's
    process."""
    taps = ((pair.master_ns, pair.master_if), (pair.slave_ns, pair.slave_if))
    m = pysoem_master(pair, n, period_us)
    try:
        run = cycles(m, seconds, period_us, daemon_pid, spin=spin)
        with Capture.both_ends(*taps) as rt:
            cycles(m, seconds, period_us, daemon_pid, spin=spin)
        run["reply_us"] = rt.stats()
        if echo is None:
            return run
        os.kill(daemon_pid, signal.SIGSTOP)  # the daemon is frozen, its socket idle
        proc = subprocess.Popen(echo_command(pair.slave_ns, pair.slave_if, echo, echo_mode, pin))
        try:
            time.sleep(0.3)
            floor = cycles(m, seconds, period_us, proc.pid, lock=False, spin=spin)
            with Capture.both_ends(*taps) as ft:
                cycles(m, seconds, period_us, proc.pid, lock=False, spin=spin)
            run["floor_reply_us"] = ft.stats()
        finally:
            proc.kill()
            proc.wait()
            os.kill(daemon_pid, signal.SIGCONT)
        run["floor_rtt_us"] = floor["rtt_us"]
        run["floor_lost"] = floor["lost"]
        run["ratio_median"] = round(run["rtt_us"]["median"] / floor["rtt_us"]["median"], 2)
        return run
    finally:
        m.close()


def max_rate(n: int, extra: tuple[str, ...], hold_s: float, rates: Sequence[int],
             tmp: Path, spin: bool, echo: Path | None = None,
             echo_mode: str = "block") -> dict[str, Any]:  # fmt: skip
    """The highest of ``rates`` (Hz) that holds 0 lost frames and 0 WKC errors for
    ``hold_s`` seconds, SYNC0 at the same rate; each rate on a fresh daemon and bring-up
    (the 10-minute runs: ``--rates 1000 --hold 600``). Every hold tried is kept in
    ``tried``; ``rate_hz`` is None if none held."""
    tried: list[dict[str, Any]] = []
    for period in sorted(round(1e6 / r) for r in rates):
        with NetnsPair() as pair:
            d = Daemon(pair, ("--slaves", str(n), *extra), tmp / f"rate{n}-{period}.log")
            d.start(timeout=60)
            try:
                assert d.pid is not None
                r = with_master(pair, n, period, echo, echo_mode, hold_s, [], d.pid, spin)
            finally:
                d.stop()
        print(f"      {1e6 / period:6.0f} Hz for {hold_s:g} s: lost {r['lost']} "
              f"({r['lost_master_stalled']} while the master was stalled) "
              f"wkc-err {r['wkc_errors']} cpu {r['cpu_percent']} % "
              f"rtt p99.9 {r['rtt_us']['p999']} us, steal {r['steal_s']} s"
              + (f"; fell 1 s behind after {r['cycles']} cycles" if r["fell_behind"] else "")
              + (f"; the C floor, same hold: lost {r['floor_lost']}" if echo else ""))  # fmt: skip
        tried.append(r)
        if r["lost"] == 0 and r["wkc_errors"] == 0 and not r["fell_behind"]:
            return {"rate_hz": round(1e6 / period), "hold_s": hold_s, "tried": tried}
    return {"rate_hz": None, "hold_s": hold_s, "tried": tried}


def repeated(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per mode, placement and N measured more than once (``--repeat``): the median of the
    runs' ratios and round trips, with the range of the ratios; printed as it is returned."""
    groups: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for r in runs:
        groups.setdefault((r["mode"], r["placement"], r["slaves"]), []).append(r)
    out = []
    for (mode, placement, n), rs in groups.items():
        ratios = sorted(r["ratio_median"] for r in rs)
        row = {"mode": mode, "placement": placement, "slaves": n, "runs": len(rs),
               "ratio_median": statistics.median(ratios), "ratio_min": ratios[0],
               "ratio_max": ratios[-1],
               "rtt_median_us": statistics.median(r["rtt_us"]["median"] for r in rs),
               "floor_median_us": statistics.median(r["floor_rtt_us"]["median"] for r in rs),
               "cpu_percent_median": statistics.median(r["cpu_percent"] for r in rs)}  # fmt: skip
        out.append(row)
        print(f"{mode:9s} {placement:8s} N={n:3d} {len(rs)} runs: median ratio "
              f"x{row['ratio_median']} (x{ratios[0]}-{ratios[-1]}), round trip "
              f"{row['rtt_median_us']} us, floor {row['floor_median_us']} us, daemon "
              f"{row['cpu_percent_median']} %")  # fmt: skip
    return out


def machine() -> dict[str, Any]:
    """The machine a run was made on."""
    cpu_model = next((ln.split(":", 1)[1].strip() for ln in
                      Path("/proc/cpuinfo").read_text().splitlines()
                      if ln.startswith("model name")), platform.machine())  # fmt: skip
    return {"machine": platform.node(), "cpus": os.cpu_count(), "cpu_model": cpu_model,
            "kernel": platform.release(), "python": platform.python_version()}  # fmt: skip


def line(mode: str, placement: str, n: int, run: dict[str, Any], row: dict[str, Any],
         rate: dict[str, Any] | None) -> str:  # fmt: skip
    """One run's line of the table."""
    held = ""
    if rate is not None:
        held = f"  held {rate['rate_hz']} Hz" if rate["rate_hz"] else "  no rate held"
    return (f"{mode:9s} {placement:8s} N={n:3d} pysoem median "
            f"{run['rtt_us']['median']:7.1f} p99 {run['rtt_us']['p99']:7.1f} us, "
            f"floor {run['floor_rtt_us']['median']:7.1f} us "
            f"(x{run['ratio_median']})  lost {run['lost']} wkc-err "
            f"{run['wkc_errors']}  daemon {run['cpu_per_cycle_us']} us/cycle "
            f"{run['cpu_percent']} %  enabled {run['drives_enabled']}/{n}  raw frame "
            f"x{row['raw_ratio_median']}  daemon reply median "
            f"{run['reply_us']['median']} p99.99 {run['reply_us']['p99.99']} max "
            f"{run['reply_us']['max']} us (floor "
            f"{run.get('floor_reply_us', {}).get('median')})"
            + held + wkc_seen_text(run))  # fmt: skip


def run(args: BenchOptions) -> int:
    """The round-trip benchmark with the options of ``ecatsim bench``."""
    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-bench-"))
    echo = build_echo(tmp / "echo")
    frame = dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, 0, bytes(29))])
    out: dict[str, Any] = {**machine(), "master_spin": args.master_spin, "runs": []}
    all_cpus = os.sched_getaffinity(0)
    for mode in args.modes:
        busy = mode == "busy-poll"
        echo_mode = "busy" if busy else "block"
        for placement in args.placements:
            cpu = args.cpu if placement == "unpinned" else (args.cpu or 0)
            pin = ["taskset", "-c", str(cpu)] if cpu is not None else []
            extra = (*(("--busy-poll",) if busy else ()),
                     *(("--cpu", str(cpu)) if cpu is not None else ()),
                     *args.scheduling_flags())  # fmt: skip
            os.sched_setaffinity(0, all_cpus if cpu is None or placement == "unpinned" else {cpu})
            for n in [n for n in args.slaves for _ in range(args.repeat)]:
                with NetnsPair() as pair:
                    proc = subprocess.Popen(
                        echo_command(pair.slave_ns, pair.slave_if, echo, echo_mode, pin)
                    )
                    time.sleep(0.2)
                    floor_raw, floor_lost = raw_rtt(pair, frame, 2000)
                    proc.kill()
                    proc.wait()
                    d = Daemon(pair, ("--slaves", str(n), *extra),
                               tmp / f"daemon{n}{mode}{placement}.log")  # fmt: skip
                    d.start(timeout=60)
                    try:
                        raw, raw_lost = raw_rtt(pair, frame, 2000)
                        assert d.pid is not None
                        r = with_master(pair, n, args.period_us, echo, echo_mode,
                                        args.seconds, pin, d.pid, args.master_spin)  # fmt: skip
                    finally:
                        d.stop()
                rate = None
                if args.max_rate:
                    floor_echo = echo if args.hold_floor else None
                    rate = max_rate(n, extra, args.hold, args.rates, tmp, args.master_spin,
                                    floor_echo, echo_mode)  # fmt: skip
                fl, em = stats(floor_raw), stats(raw)
                row = {"mode": mode, "placement": placement, "slaves": n, **r,
                       "raw_floor_rtt_us": fl, "raw_rtt_us": em,
                       "raw_ratio_median": round(em["median"] / fl["median"], 2),
                       "raw_lost": raw_lost + floor_lost, "max_rate": rate}  # fmt: skip
                out["runs"].append(row)
                print(line(mode, placement, n, r, row, rate))
    if args.repeat > 1:
        out["repeated"] = repeated(out["runs"])
    results.write(args.results, "bench", out)
    shutil.rmtree(tmp, ignore_errors=True)  # a run that fails keeps its daemon logs there
    return 0
