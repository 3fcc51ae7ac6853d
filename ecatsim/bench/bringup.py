"""``ecatsim bench --bringup N [--cycles K]``: every frame of a bring-up and of K cycles,
timed at the master's end of the link.

A pysoem master in its own network namespace brings N TMC8670 drives to OP with DC (SYNC0
every cycle), as the round-trip bench does: config_init, config_dc with SYNC0 on every
slave, csp by SDO, config_map (or config_overlap_map, ``--overlap``: SOEM's IO map then
holds inputs and outputs of a slave in the same bytes), SAFEOP, OP; then K cycles at the
period with every drive enabled and moving. A packet socket on the master's interface
(:meth:`ecatsim.bench.capture.Capture.master_end`) stamps every request and reply; each
is paired and timed, per phase and overall: p50, p99.9, max, how many over 1 ms and over
2 ms (SOEM's, pysoem's and KickCAT's default timeout), resends, unanswered frames and the
slowest frames by command and address. The cycles add lost frames, cycles whose WKC
fell short of the expected one, and the reply times of each of a cycle's frames by its
logical address (:func:`ecatsim.bench.capture.cycle_frames`). Results: a summary on
stdout and bringup-<N>-<time>.json in the results directory.

With ``--master soem`` SOEM's own DC sample red_test is the master instead
(:mod:`ecatsim.bench.redtest`): up to 1023 slaves and a 64 KiB IO map, the cycles' lost
frames and WKCs read off the wire. Each run records its master, the master's limits,
overlap or not, and the daemon's flags. A watch on every CPU records the host's stalls
during the run and how many replies over 2 ms came during one
(:mod:`ecatsim.bench.stallwatch`), and each daemon's ``stopped`` log line (SYNC0 pulses
merged, collector pauses, failures) is kept with the run (decision B8).
Ref: docs/performance.md "How to measure".
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Protocol

from ecatsim.bench import redtest, results, soem, steadiness
from ecatsim.bench.capture import (
    Capture,
    Frame,
    analyse,
    cycle_frames,
    late_replies,
    process_cycles,
)
from ecatsim.bench.master import CSP, cpu_seconds, cycles, request_op
from ecatsim.bench.netns import Daemon, ExtraNetns, NetnsPair, Port, SlaveEnd, in_netns
from ecatsim.bench.options import BenchOptions
from ecatsim.bench.stallwatch import StallWatch

#: pysoem's limits: SOEM's EC_MAXSLAVE 200 (entry 0 is the master's) and its fixed IO map
PYSOEM_LIMITS = {"max_slaves": 199, "iomap_bytes": 4096, "sync0": True, "drives_enabled": True}


class Marks(Protocol):
    """Where a bring-up marks its phases: a capture, or nothing (:class:`Unmarked`)."""

    def mark(self, name: str) -> None: ...


class Unmarked:
    """No marks: the bring-up of the master that ``--restart`` closes before the timed one."""

    def mark(self, name: str) -> None:
        return None


def bring_up(m: Any, cap: Marks, pair: NetnsPair, n: int, period_us: int,
             overlap: bool) -> None:  # fmt: skip
    """The bring-up, each phase marked in the capture."""
    import pysoem

    with in_netns(pair.master_ns):
        m.open(pair.master_if)
    cap.mark("config_init")
    found = m.config_init()
    if found != n:
        raise SystemExit(f"bench: the master found {found} slaves, not {n}")
    cap.mark("config_dc")
    m.config_dc()
    for s in m.slaves:
        s.dc_sync(True, period_us * 1000)
    cap.mark("sdo")
    for s in m.slaves:
        s.sdo_write(0x6060, 0, bytes([CSP]))  # cyclic synchronous position
    cap.mark("config_map")
    used = m.config_overlap_map() if overlap else m.config_map()
    if used > PYSOEM_LIMITS["iomap_bytes"]:
        # SOEM keeps the inputs after the outputs in the IO map in both modes (overlap
        # only shortens the frames): pysoem's fixed map would be overrun by the replies
        raise SystemExit(
            f"bench: {n} drives need {used} bytes of IO map, pysoem's holds "
            f"{PYSOEM_LIMITS['iomap_bytes']}: use --master soem"
        )
    cap.mark("safeop")
    if m.state_check(pysoem.SAFEOP_STATE, 5_000_000) != pysoem.SAFEOP_STATE:
        raise SystemExit("bench: the segment did not reach SAFEOP")
    cap.mark("op")
    if not request_op(m, 5000, 2000, 2000, overlap):
        raise SystemExit("bench: the segment did not reach OP")


def scheduling_text(rt: int | None, cpu: int | None) -> str:
    """How the master is scheduled, as the results record it."""
    return (f"SCHED_FIFO {rt}" if rt is not None else "ordinary") + (
        f", CPU {cpu}" if cpu is not None else ", unpinned"
    )


@contextmanager
def master_scheduling(rt: int | None, cpu: int | None) -> Iterator[str]:
    """The master's thread SCHED_FIFO at ``rt`` and pinned to ``cpu`` (each if given) for
    the bring-up and the cycles, as a real-time master runs; yields what it set."""
    policy, affinity = os.sched_getscheduler(0), os.sched_getaffinity(0)
    param = os.sched_getparam(0)
    try:
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})
        if rt is not None:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt))
        yield scheduling_text(rt, cpu)
    finally:
        os.sched_setscheduler(0, policy, param)
        os.sched_setaffinity(0, affinity)


#: a reply this late (us) is lost to a master with the default timeout
LATE_US = 2000
#: the fields of each daemon's ``stopped`` log line kept in the JSON (``daemons``)
STOPPED_FIELDS = ("frames", "replies", "compiled_replies", "bad_frames", "sync0_pulses",
                  "sync0_max_late_us", "sync0_deferred", "sync0_merged", "failures",
                  "cpu_moves", "cpu_follow_pauses", "gc_collections", "gc_max_us",
                  "reply_max_us", "replies_over_1ms", "replies_over_2ms", "pickup_max_us",
                  "late_picked_up_late")  # fmt: skip
#: of those, the ones the summary prints
DAEMON_SUMMARY = ("sync0_merged", "sync0_max_late_us", "failures", "gc_max_us",
                  "replies_over_2ms", "late_picked_up_late", "reply_max_us")  # fmt: skip


def stopped_counts(d: Daemon) -> dict[str, Any]:
    """The :data:`STOPPED_FIELDS` of the daemon's ``stopped`` log line; {} when it has
    none (it was killed)."""
    event = d.last_event("stopped")
    return {k: event[k] for k in STOPPED_FIELDS if k in event}


def observed(watch: StallWatch, found: list[Frame], ds: list[Daemon]) -> dict[str, Any]:
    """What a run records besides the master's figures (decision B8): the host during the
    run against the replies later than :data:`LATE_US` and those later than 1 ms
    (``host_stalls``), and each daemon's :func:`stopped_counts` (``daemons``)."""
    over_1ms = late_replies(found, 1000)
    late = [(a, b) for a, b in over_1ms if b - a >= LATE_US * 1000]
    return {"host_stalls": watch.report(late, over_1ms=over_1ms),
            "daemons": [stopped_counts(d) for d in ds]}  # fmt: skip


def chain_sizes(n: int, chain: int) -> list[int]:
    """``n`` drives over ``chain`` daemons, as even as they go (the first ones take the
    remainder)."""
    return [n // chain + (k < n % chain) for k in range(chain)]


def chain_flags(k: int, chain: int, extra: tuple[str, ...]) -> tuple[str, ...]:
    """Daemon ``k``'s scheduling flags: ``extra``, and in a chain of more than one (unless
    ``extra`` pins it) its own CPU, ``k`` modulo the CPUs this process may use."""
    if chain == 1 or "--cpu" in extra:
        return extra
    cpus = sorted(os.sched_getaffinity(0))
    return (*extra, "--cpu", str(cpus[k % len(cpus)]))


@contextmanager
def daemons(pair: NetnsPair, n: int, chain: int, extra: tuple[str, ...],
            tmp: Path) -> Iterator[list[Daemon]]:  # fmt: skip
    """``n`` drives in ``chain`` daemons, one segment to the master: the first on the
    pair's slave end, each next one in a namespace of its own behind the previous one's
    ``--out-iface`` (a veth), started from the last. Stopped and removed on exit."""
    with ExitStack() as stack:
        ends: list[SlaveEnd] = [pair]
        outs: list[str] = []
        for _ in range(1, chain):
            x = stack.enter_context(ExtraNetns())
            here, there = x.veth(ends[-1].slave_ns)
            ends.append(Port(x.ns, here))
            outs.append(there)
        started: list[Daemon] = []
        try:
            for k, size in reversed(list(enumerate(chain_sizes(n, chain)))):
                out = ("--out-iface", outs[k]) if k < chain - 1 else ()
                args = ("--slaves", str(size), *out, *chain_flags(k, chain, extra))
                d = Daemon(ends[k], args, tmp / f"daemon{n}-{k}.log")
                started.insert(0, d)
                d.start(timeout=120)
            yield started
        finally:
            for d in started:
                d.stop()


def daemon_pids(ds: list[Daemon]) -> list[int]:
    """The running daemons' process ids."""
    pids = [d.pid for d in ds]
    assert all(p is not None for p in pids)
    return [p for p in pids if p is not None]


def run_bringup(n: int, cycles_k: int, period_us: int, overlap: bool,
                extra: tuple[str, ...], spin: bool = False, master_rt: int | None = None,
                master_cpu: int | None = None, chain: int = 1,
                restart: bool = False) -> dict[str, Any]:  # fmt: skip
    """One bring-up of ``n`` drives (in ``chain`` chained daemons) and ``cycles_k`` cycles
    on fresh daemons; the master scheduled as :func:`master_scheduling` says. With
    ``restart``, the timed bring-up is a second master's: the first brought the drives to
    OP, ran 200 cycles and closed."""
    import pysoem

    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-bringup-"))
    failure = ""
    with NetnsPair() as pair, daemons(pair, n, chain, extra, tmp) as ds:
        pids = daemon_pids(ds)
        if restart:
            first = pysoem.Master()
            try:
                bring_up(first, Unmarked(), pair, n, period_us, overlap)
                cycles(first, 200 * period_us / 1e6, period_us, pids[0], spin=spin,
                       overlap=overlap)  # fmt: skip
            finally:
                first.close()
        m = pysoem.Master()
        try:
            with (
                Capture.master_end(pair.master_ns, pair.master_if) as cap,
                StallWatch() as watch,  # on every CPU: before the master is pinned
                master_scheduling(master_rt, master_cpu) as master,
            ):
                t0 = time.perf_counter()
                try:
                    bring_up(m, cap, pair, n, period_us, overlap)
                except master_errors(pysoem) as e:  # said below, with the host
                    failure = (
                        str(e.code) if isinstance(e, SystemExit) else f"{type(e).__name__} {e}"
                    )
                    cap.mark("end")
                    time.sleep(0.05)
                    raise _MasterGaveUp from e
                bring_up_s = time.perf_counter() - t0
                cap.mark("cycles")
                cpu0, wall0 = [cpu_seconds(p) for p in pids], time.perf_counter()
                cyc = cycles(
                    m, cycles_k * period_us / 1e6, period_us, pids[0], spin=spin, overlap=overlap
                )
                wall = time.perf_counter() - wall0
                each = [
                    round((cpu_seconds(p) - c) / wall * 100, 1)
                    for p, c in zip(pids, cpu0, strict=True)
                ]
                cap.mark("end")
                time.sleep(0.05)
        except _MasterGaveUp:
            pass
        finally:
            m.close()
    found = cap.frames()
    if failure:
        raise SystemExit(gave_up(failure, found, watch))
    frames = analyse(found, cap.marks)
    frames.get("phases", {}).pop("end", None)
    marks = dict((name, t) for t, name in cap.marks)
    if "cycles" in marks:
        end = marks.get("end", time.time_ns())
        frames["cycle_frames"] = cycle_frames(found, marks["cycles"], end)
    kept = {k: cyc[k] for k in ("cycles", "lost", "wkc_errors", "expected_wkc", "wkc_error_seen",
                                "cpu_percent", "rtt_us", "fell_behind", "lost_master_stalled",
                                "drives_enabled", "steal_s")}  # fmt: skip
    return {"slaves": n, "overlap": overlap, "period_us": period_us, "master": master,
            "master_name": f"pysoem {soem.pysoem_version()}", "master_limits": PYSOEM_LIMITS,
            "restart": restart,
            "daemon_flags": list(extra), "chain": chain_text(n, chain, extra),
            "bring_up_s": round(bring_up_s, 2), "frames": frames,
            "cycles": {**kept, "daemon_cpu_percent": each},
            **observed(watch, found, ds)}  # fmt: skip


def master_errors(pysoem: Any) -> tuple[type[BaseException], ...]:
    """The errors of a master that gives up on the segment: pysoem's, and the bring-up's
    own (SystemExit: too few slaves, no SAFEOP, no OP)."""
    names = ("ConfigMapError", "SdoError", "PacketError", "MailboxError", "WkcError",
             "EepromError")  # fmt: skip
    return (SystemExit, *(getattr(pysoem, k) for k in names))


class _MasterGaveUp(Exception):
    """The timed master's bring-up ended in one of its errors (``run_bringup``)."""


def gave_up(failure: str, found: list[Frame], watch: StallWatch) -> str:
    """One line for a bring-up the master gave up: its error, and the replies the capture
    saw later than a stock master waits (2 ms) with the host's stalls during the run
    (decision B8), the common cause on a host that stalls."""
    late = late_replies(found, LATE_US)
    return (f"bench: the master gave up during its bring-up: {failure}; "
            + StallWatch.text(watch.report(late)))  # fmt: skip


def chain_text(n: int, chain: int, extra: tuple[str, ...]) -> list[dict[str, Any]]:
    """Each daemon of the segment: its drives and its own flags (the JSON's ``chain``)."""
    return [{"slaves": size, "flags": list(chain_flags(k, chain, extra))}
            for k, size in enumerate(chain_sizes(n, chain))]  # fmt: skip


def run_bringup_soem(n: int, cycles_k: int, period_us: int, overlap: bool,
                     extra: tuple[str, ...], master_rt: int | None = None,
                     master_cpu: int | None = None, sync0: bool = False, chain: int = 1
                     ) -> dict[str, Any]:  # fmt: skip
    """One bring-up of ``n`` drives (in ``chain`` chained daemons) and about ``cycles_k``
    cycles (red_test's 20 ms loops) on fresh daemons with SOEM's red_test as the master
    (:mod:`ecatsim.bench.redtest`); ``master_rt``/``master_cpu`` as ``chrt``/``taskset``
    (its cycle thread sets SCHED_FIFO 40 itself)."""
    exe = soem.red_test(cycles_k, period_us, overlap, sync0)
    prefix: tuple[str, ...] = ()
    if master_cpu is not None:
        prefix += ("taskset", "-c", str(master_cpu))
    if master_rt is not None:
        prefix += ("chrt", "-f", str(master_rt))
    sched = scheduling_text(master_rt, master_cpu) + "; cycle thread SCHED_FIFO 40"
    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-bringup-"))
    with (
        NetnsPair() as pair,
        daemons(pair, n, chain, extra, tmp) as ds,
        Capture.master_end(pair.master_ns, pair.master_if, keep_wkc=True) as cap,
        StallWatch() as watch,
    ):
        t0 = time.perf_counter()
        rt = redtest.run(exe, pair, cap, period_us, daemon_pids(ds), prefix,
                         redtest.run_timeout(cycles_k, period_us))  # fmt: skip
        time.sleep(0.05)
    marks = dict((name, t) for t, name in cap.marks)
    if rt.slaves != n or "safeop_dc" not in marks:
        tail = "\n  ".join(rt.tail)
        raise SystemExit(f"bench: red_test configured {rt.slaves} of {n} slaves; its last "
                         f"lines:\n  {tail}")  # fmt: skip
    found = cap.frames()
    frames = analyse(found, cap.marks)
    frames.get("phases", {}).pop("end", None)
    # without OP the cycles are the ones red_test ran while it waited for OP
    start = marks["cycles"] if rt.all_op else marks["op"]
    end = marks.get("end", time.time_ns())
    cyc = process_cycles(found, start, end, rt.expected_wkc, redtest.timeout_ns(period_us))
    frames["cycle_frames"] = cycle_frames(found, start, end)
    wall_s = rt.cycles_wall_ns / 1e9
    each = [round(c / wall_s * 100, 1) for c in rt.cycles_cpu_s] if wall_s else []
    cyc.update(cpu_percent=each[0] if each else None, daemon_cpu_percent=each,
               drives_enabled=rt.drives_enabled, all_op=rt.all_op, master_exit=rt.returncode,
               master_reports=rt.trouble)  # fmt: skip
    return {"slaves": n, "overlap": overlap, "period_us": period_us, "master": sched,
            "master_name": f"{redtest.NAME} (pysoem {soem.pysoem_version()} sdist)",
            "master_limits": redtest.limits(sync0), "daemon_flags": list(extra),
            "chain": chain_text(n, chain, extra),
            "bring_up_s": round((marks.get("cycles", marks["op"]) - marks["config"]) / 1e9, 2),
            "run_s": round(time.perf_counter() - t0, 2), "frames": frames,
            "cycles": cyc, **observed(watch, found, ds)}  # fmt: skip


def chained(r: dict[str, Any]) -> str:
    """ ", in K chained daemons of A/B/... drives" for a chain, else nothing."""
    chain = r.get("chain", [])
    if len(chain) < 2:
        return ""
    return (
        f", in {len(chain)} chained daemons of {'/'.join(str(d['slaves']) for d in chain)} drives"
    )


def summary(r: dict[str, Any]) -> str:
    """One bring-up's figures: the totals, each phase, the host's steadiness before the run,
    the five slowest frames."""
    f, c = r["frames"], r["cycles"]
    enabled = c["drives_enabled"]
    lines = [f"N={r['slaves']} ({'overlap map' if r['overlap'] else 'map'}, master "
             f"{r.get('master_name', 'pysoem')}"
             f"{'' if r.get('master_limits', {}).get('sync0', True) else ' without SYNC0'} "
             f"{r['master']}{', restarted' if r.get('restart') else ''}, daemon "
             f"{' '.join(r['daemon_flags']) or 'default flags'}{chained(r)}) bring-up "
             f"{r['bring_up_s']} s, {c['cycles']} cycles: {f['frames']} frames, reply p50 "
             f"{f['p50_us']} p99.9 {f['p999_us']} max {f['max_us']} us, over 1 ms "
             f"{f['over_1ms']}, over 2 ms {f['over_2ms']}, resends {f['resends']}, "
             f"unanswered {f['unanswered']}; cycles lost {c['lost']}, WKC short "
             f"{c['wkc_errors']} (expected {c['expected_wkc']}), daemon "
             f"{'/'.join(str(x) for x in c.get('daemon_cpu_percent') or [c['cpu_percent']])} %, "
             f"{'' if c.get('all_op', True) else 'NOT ALL IN OP, '}"
             f"{'MASTER KILLED, ' if c.get('master_exit', 0) == -9 else ''}"
             f"enabled {'not asked' if enabled is None else enabled}/{r['slaves']}"]  # fmt: skip
    for name, p in f.get("phases", {}).items():
        lines.append(f"  {name:12s} {p['frames']:6d} frames  p50 {p['p50_us']:8.1f}  p99.9 "
                     f"{p['p999_us']:8.1f}  max {p['max_us']:8.1f} us  >1ms {p['over_1ms']}  "
                     f">2ms {p['over_2ms']}")  # fmt: skip
    if "host_steadiness" in r:
        lines.append("  " + steadiness.text(r["host_steadiness"]))
    if "host_stalls" in r:
        lines.append("  " + StallWatch.text(r["host_stalls"]))
    for k, d in enumerate(r.get("daemons", [])):
        lines.append(f"  daemon {k}: " + ", ".join(f"{key} {d[key]}" for key in DAEMON_SUMMARY
                                                   if key in d))  # fmt: skip
    if f.get("cycle_frames"):
        lines.append("  a cycle's frames: " + ", ".join(
            f"{g['cmd']} {g['logical']} p50 {g['p50_us']} p99.9 {g['p999_us']} us"
            for g in f["cycle_frames"]))  # fmt: skip
    for s in f["slowest"][:5]:
        lines.append(f"  slowest: {s['us']} us {s['cmd']} adp {s['adp']} ado {s['ado']} "
                     f"len {s['length']}")  # fmt: skip
    return "\n".join(lines)


def run(args: BenchOptions) -> int:
    """Each size of ``--bringup`` ``--repeat`` times; prints and writes bringup-*.json."""
    extra = args.scheduling_flags()
    if args.cpu is not None:
        extra = (*extra, "--cpu", str(args.cpu))
    out: dict[str, Any] = {"when": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
                           "machine": platform.node(), "cpus": os.cpu_count(),
                           "load_1min": os.getloadavg()[0],
                           "python": platform.python_version(), "runs": []}  # fmt: skip
    for n in [n for n in args.bringup for _ in range(args.repeat)]:
        host = steadiness.measure()  # what the host's CPUs did just before (decision B7)
        if args.master == "soem":
            r = run_bringup_soem(n, args.cycles, args.period_us, args.overlap, extra,
                                 args.master_rt, args.master_cpu, args.sync0,
                                 args.chain)  # fmt: skip
        else:
            r = run_bringup(n, args.cycles, args.period_us, args.overlap, extra,
                            args.master_spin, args.master_rt, args.master_cpu,
                            args.chain, args.restart)  # fmt: skip
        r["host_steadiness"] = host
        out["runs"].append(r)
        print(summary(r), flush=True)
    results.write(args.results, f"bringup-{'-'.join(str(n) for n in args.bringup)}", out)
    return 0
