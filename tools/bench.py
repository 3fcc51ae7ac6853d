"""Benchmark: the daemon against a real master and against a C echo floor, same run.

    .venv/bin/ecatsim bench --slaves 1 --slaves 4 --slaves 16 --seconds 10
    .venv/bin/ecatsim bench --modes blocking --modes busy-poll --max-rate --hold 60
    .venv/bin/python tools/bench.py --help     (the same command; root)

For each N it starts the daemon (N TMC8670 drives) in a private network namespace, brings
the segment to OP with pysoem (DC active, SYNC0 every cycle) in another, runs cyclic
exchange kept mid-way between SYNC0 pulses with every drive enabled in csp and moving, and
records the round trip of each send_processdata()/receive_processdata() pair, lost frames,
WKC mismatches, the daemon's CPU time and its own reply time to each frame from kernel
timestamps on both ends of the link (tools/reply_time.py). Then the daemon is frozen and the
floor, a minimal C responder compiled here with the system compiler, answers the same
master's same frames in
the same wake-up mode: the ratio of the medians is the figure the targets use. Each run is
made unpinned and with master, daemon and floor pinned to one CPU (docs/performance.md "How to
measure"). A raw LRW frame timed before bring-up (slaves in INIT) is reported too. Results: a
table on stdout and JSON in bench/results/. Ref: docs/performance.md.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import signal
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.bench_cli import BenchOptions  # noqa: E402
from ecatsim.wire import datagram as dg  # noqa: E402
from tests.integration.netns import Daemon, NetnsPair, in_netns  # noqa: E402

sys.path.insert(0, str(ROOT / "tools"))
from reply_time import ReplyTimer  # noqa: E402

CSP = 8
#: TMC8670 default PDOs (config/tmc8670.yaml): 6040h, 607Ah, 6071h, 60FFh out; 6041h,
#: 6061h, 6064h, 6077h, 606Ch, 60FDh in
RX = struct.Struct("<HihI")
TX = struct.Struct("<HbihiI")

ECHO_C = r"""
#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <sys/socket.h>
#include <string.h>
#include <stdio.h>
int main(int argc, char **argv) {
    int s = socket(AF_PACKET, SOCK_RAW, htons(0x88A4));
    struct sockaddr_ll a; memset(&a, 0, sizeof a);
    a.sll_family = AF_PACKET; a.sll_protocol = htons(0x88A4);
    a.sll_ifindex = if_nametoindex(argv[1]);
    if (s < 0 || bind(s, (struct sockaddr *)&a, sizeof a) < 0) { perror("echo"); return 1; }
    int busy = argc > 2 && strcmp(argv[2], "busy") == 0;  /* the same wake-up mode */
    unsigned char buf[2048];
    for (;;) {
        ssize_t n = recv(s, buf, sizeof buf, busy ? MSG_DONTWAIT : 0);
        if (n < 30 || (buf[6] & 2)) continue;       /* our own replies come back too */
        buf[6] |= 2;                                 /* processed: source MAC bit 1 */
        unsigned len = (buf[22] | (buf[23] << 8)) & 0x7FF;
        unsigned w = 26 + len;                        /* first datagram's WKC */
        if (w + 2 <= (unsigned)n) buf[w] += 1;
        send(s, buf, n, 0);
    }
}
"""


def percentile(sorted_us: list[float], q: float) -> float:
    return sorted_us[min(len(sorted_us) - 1, int(len(sorted_us) * q))]


def stats(rtts: list[float]) -> dict[str, float]:
    us = sorted(r * 1e6 for r in rtts)
    return {
        "min": round(us[0], 1),
        "median": round(percentile(us, 0.5), 1),
        "p99": round(percentile(us, 0.99), 1),
        "p999": round(percentile(us, 0.999), 1),
        "max": round(us[-1], 1),
    }


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


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def steal_seconds() -> list[float]:
    """Time the hypervisor ran something else on each of this VM's CPUs (steal time,
    the 8th field of each cpuN line of /proc/stat), in seconds; zeros on bare metal."""
    tck = os.sysconf("SC_CLK_TCK")
    return [int(ln.split()[8]) / tck for ln in Path("/proc/stat").read_text().splitlines()
            if ln.startswith("cpu") and ln[3:4].isdigit()]  # fmt: skip


def pysoem_master(pair: NetnsPair, n: int, period_us: int) -> Any:
    """A pysoem master with the segment in OP, DC active (SYNC0 every cycle)."""
    import pysoem

    m = pysoem.Master()
    with in_netns(pair.master_ns):
        m.open(pair.master_if)
    found = m.config_init()
    if found != n:
        m.close()
        raise SystemExit(f"bench: the master found {found} slaves, not {n}")
    m.config_dc()
    for s in m.slaves:
        s.dc_sync(True, period_us * 1000)
        s.sdo_write(0x6060, 0, bytes([CSP]))  # cyclic synchronous position
    m.config_map()
    m.state_check(pysoem.SAFEOP_STATE, 5_000_000)
    m.state = pysoem.OP_STATE
    m.send_processdata()
    m.receive_processdata(50_000)
    m.write_state()
    for _ in range(500):
        m.send_processdata()
        m.receive_processdata(50_000)
        if m.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
            break
    if m.read_state() != pysoem.OP_STATE:
        m.close()
        raise SystemExit("bench: the segment did not reach OP")
    return m


class CspMotion:
    """Every drive enabled in csp and moving, as a master does it: controlword 6, 7, 15, each
    sent until the statusword shows the state (a DC drive acts only once SYNC0 runs), then a
    cosine of ``AMPLITUDE`` counts at 0.5 Hz from where the drive stands."""

    AMPLITUDE = 4096
    #: (controlword, statusword mask, statusword wanted): CiA 402-2 Figure 5
    STEPS = ((0x06, 0x6F, 0x21), (0x07, 0x6F, 0x23), (0x0F, 0x6F, 0x27))

    def __init__(self, m: Any, period_us: int) -> None:
        self.m = m
        self.dt = period_us / 1e6
        self.step = [0] * len(m.slaves)
        self.k = [0] * len(m.slaves)
        self.start = [TX.unpack(bytes(s.input))[2] for s in m.slaves]

    def outputs(self) -> None:
        for i, s in enumerate(self.m.slaves):
            sw = TX.unpack(bytes(s.input))[0]
            st = self.step[i]
            cw, mask, want = self.STEPS[st]
            if sw & mask == want and st < len(self.STEPS) - 1:
                st = self.step[i] = st + 1
                cw = self.STEPS[st][0]
            x = 0.0
            if sw & 0x6F == 0x27:
                self.k[i] += 1
                x = self.AMPLITUDE * (1.0 - math.cos(math.pi * self.k[i] * self.dt)) / 2.0
            s.output = RX.pack(cw, self.start[i] + round(x), 0, 0)


#: --master-spin: the master waits for its next cycle spinning, not in time.sleep(), so its
#: CPU never halts between cycles (a halted vCPU can be slow to come back on a VM)
MASTER_SPIN = False


def cycles(m: Any, seconds: float, period_us: int, pid: int, lock: bool = True) -> dict[str, Any]:
    """Cyclic exchange for ``seconds``: round trips, lost frames (no reply within two
    periods), WKC mismatches, the daemon's CPU per cycle and in % of one core, the VM's
    steal time per CPU. A lost frame whose receive call took more than a millisecond past
    its timeout is also counted in ``lost_master_stalled``: the master itself was off its
    CPU while it waited, and may have missed a reply that had arrived. It stops
    early, ``fell_behind``, once the cycle runs a whole second late (the rate is not
    kept: replies come slower than the period). Every cycle the master computes the csp
    motion's outputs from the inputs, against the daemon and against the echo alike, so
    that what its own work leaves in the caches before each frame is the same for both. With
    ``lock`` the cycle is kept mid-way between SYNC0 pulses by the DC time of the replies,
    as SOEM's examples do (ec_sync); the echo has no DC clock."""
    rtts, lost, wkc_err = [], 0, 0
    lost_waits: list[int] = []  # how long the master's send + receive took for each lost frame
    #: (WKC, send + receive in us) of each mismatch: SOEM splits a process image larger than
    #: one frame into several LRWs and sums the WKCs of those that came back in time, so a
    #: late frame of two reads as a WKC below the expected one, not as a lost cycle
    wkc_seen: list[tuple[int, int]] = []
    cycle_ns = period_us * 1000
    sync0 = struct.unpack("<Q", m.slaves[0]._fprd(0x0990, 8))[0] if lock else None
    cpu0, wall0, steal0 = cpu_seconds(pid), time.perf_counter(), steal_seconds()
    t_next = wall0
    n = max(1, int(seconds * 1e6 / period_us))
    motion = CspMotion(m, period_us)
    done, behind = 0, False
    for _ in range(n):
        if time.perf_counter() - t_next > 1.0:
            behind = True  # a whole second behind the schedule: this rate is not kept
            break
        done += 1
        motion.outputs()
        t = time.perf_counter()
        m.send_processdata()
        w = m.receive_processdata(2 * period_us)
        rtts.append(time.perf_counter() - t)
        if w < 0:
            lost += 1
            lost_waits.append(round(rtts[-1] * 1e6))
        elif w != m.expected_wkc:
            wkc_err += 1
            wkc_seen.append((w, round(rtts[-1] * 1e6)))
        t_next += period_us / 1e6
        if sync0 is not None and w > 0:
            t_next += 0.1 * (cycle_ns / 2 - (m.dc_time - sync0) % cycle_ns) / 1e9
        if MASTER_SPIN:
            while time.perf_counter() < t_next:
                pass
            continue
        d = t_next - time.perf_counter()
        if d > 0:
            time.sleep(d)
    cpu, wall = cpu_seconds(pid) - cpu0, time.perf_counter() - wall0
    steal = [round(b - a, 2) for a, b in zip(steal0, steal_seconds(), strict=True)]
    enabled = sum(TX.unpack(bytes(s.input))[0] & 0x6F == 0x27 for s in m.slaves) if lock else 0
    return {"period_us": period_us, "cycles": done, "fell_behind": behind,
            "rtt_us": stats(rtts), "lost": lost, "drives_enabled": enabled,
            "wkc_errors": wkc_err, "cpu_per_cycle_us": round(cpu / done * 1e6, 1),
            "cpu_percent": round(cpu / wall * 100, 1), "steal_s": steal,
            "lost_wait_us": lost_waits[:200], "expected_wkc": m.expected_wkc,
            "wkc_error_seen": wkc_seen[:200],
            "lost_master_stalled": sum(w > 2 * period_us + 1000 for w in lost_waits)}  # fmt: skip


def wkc_seen_text(run: dict[str, Any]) -> str:
    """The WKC mismatches of a run as `` wkc seen 96/192 after 6387 us``, or nothing."""
    seen = run.get("wkc_error_seen") or []
    return "".join(f" wkc seen {w}/{run['expected_wkc']} after {us} us" for w, us in seen[:5])


def with_master(
    pair: NetnsPair,
    n: int,
    period_us: int,
    echo: Path | None,
    echo_mode: str,
    seconds: float,
    pin: list[str],
    daemon_pid: int,
) -> dict[str, Any]:
    """Cyclic exchange against the daemon, then, with the same pysoem master and frames,
    against the C echo swapped in for the daemon (docs/performance.md "How to measure").
    The round trips of both are taken with nothing else listening on the link; the reply
    times (``reply_us``, ``floor_reply_us``) in a second exchange of each, under the taps
    of tools/reply_time.py, whose thread wakes with every frame in the master's process."""
    taps = ((pair.master_ns, pair.master_if), (pair.slave_ns, pair.slave_if))
    m = pysoem_master(pair, n, period_us)
    try:
        run = cycles(m, seconds, period_us, daemon_pid)
        with ReplyTimer(*taps) as rt:
            cycles(m, seconds, period_us, daemon_pid)
        run["reply_us"] = rt.stats()
        if echo is None:
            return run
        os.kill(daemon_pid, signal.SIGSTOP)  # the daemon is frozen, its socket idle
        proc = subprocess.Popen(["ip", "netns", "exec", pair.slave_ns, *pin, str(echo),
                                 pair.slave_if, echo_mode])  # fmt: skip
        try:
            time.sleep(0.3)
            floor = cycles(m, seconds, period_us, proc.pid, lock=False)
            with ReplyTimer(*taps) as ft:
                cycles(m, seconds, period_us, proc.pid, lock=False)
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
             tmp: Path, echo: Path | None = None,
             echo_mode: str = "block") -> dict[str, Any]:  # fmt: skip
    """The highest of ``rates`` (Hz) that holds 0 lost frames and 0 WKC errors for
    ``hold_s`` seconds, SYNC0 at the same rate; each rate on a fresh daemon and bring-up
    (the issue's 10-minute runs: ``--rates 1000 --hold 600``). Every hold tried is kept
    in ``tried``; ``rate_hz`` is None if none held."""
    tried: list[dict[str, Any]] = []
    for period in sorted(round(1e6 / r) for r in rates):
        with NetnsPair() as pair:
            d = Daemon(pair, ("--slaves", str(n), *extra), tmp / f"rate{n}-{period}.log")
            d.start(timeout=60)
            try:
                assert d.pid is not None
                r = with_master(pair, n, period, echo, echo_mode, hold_s, [], d.pid)
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


def run(args: BenchOptions) -> int:
    """The whole benchmark with the options of ``ecatsim bench`` (ecatsim/bench_cli.py)."""
    global MASTER_SPIN
    MASTER_SPIN = args.master_spin
    if os.geteuid() != 0:
        print("bench: needs root (namespaces, raw sockets)", file=sys.stderr)
        return 2
    if args.bringup:
        from bringup import main as bringup_main

        rt_flags: tuple[str, ...] = ("--no-rt",) if args.no_rt else ()
        if args.rt_priority and not args.no_rt:
            rt_flags = ("--rt-priority", str(args.rt_priority))
        if args.no_follow_master_cpu:
            rt_flags = (*rt_flags, "--no-follow-master-cpu")
        if args.cpu is not None:
            rt_flags = (*rt_flags, "--cpu", str(args.cpu))
        return bringup_main(args.bringup, args.cycles, args.period_us, args.overlap, rt_flags,
                            args.repeat)  # fmt: skip
    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-bench-"))
    echo = tmp / "echo"
    subprocess.run(["cc", "-O2", "-o", str(echo), "-x", "c", "-"], input=ECHO_C.encode(),
                   check=True)  # fmt: skip
    frame = dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, 0, bytes(29))])
    cpu_model = next((ln.split(":", 1)[1].strip() for ln in
                      Path("/proc/cpuinfo").read_text().splitlines()
                      if ln.startswith("model name")), platform.machine())  # fmt: skip
    results: dict[str, Any] = {"machine": platform.node(), "cpus": os.cpu_count(),
                               "cpu_model": cpu_model,
                               "kernel": platform.release(),
                               "python": platform.python_version(),
                               "master_spin": args.master_spin, "runs": []}  # fmt: skip
    all_cpus = os.sched_getaffinity(0)
    for mode in args.modes:
        busy = mode == "busy-poll"
        echo_mode = "busy" if busy else "block"
        for placement in args.placements:
            cpu = args.cpu if placement == "unpinned" else (args.cpu or 0)
            pin = ["taskset", "-c", str(cpu)] if cpu is not None else []
            rt: tuple[str, ...] = ()
            if args.no_rt:
                rt = ("--no-rt",)
            elif args.rt_priority:
                rt = ("--rt-priority", str(args.rt_priority))
            if args.no_follow_master_cpu:
                rt = (*rt, "--no-follow-master-cpu")
            extra = (*(("--busy-poll",) if busy else ()),
                     *(("--cpu", str(cpu)) if cpu is not None else ()), *rt)  # fmt: skip
            os.sched_setaffinity(0, all_cpus if cpu is None or placement == "unpinned" else {cpu})
            for n in [n for n in args.slaves for _ in range(args.repeat)]:
                with NetnsPair() as pair:
                    proc = subprocess.Popen(["ip", "netns", "exec", pair.slave_ns, *pin,
                                             str(echo), pair.slave_if, echo_mode])  # fmt: skip
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
                        run = with_master(pair, n, args.period_us, echo, echo_mode,
                                          args.seconds, pin, d.pid)  # fmt: skip
                    finally:
                        d.stop()
                rate = None
                if args.max_rate:
                    floor_echo = echo if args.hold_floor else None
                    rate = max_rate(n, extra, args.hold, args.rates, tmp, floor_echo, echo_mode)
                fl, em = stats(floor_raw), stats(raw)
                row = {"mode": mode, "placement": placement, "slaves": n, **run,
                       "raw_floor_rtt_us": fl, "raw_rtt_us": em,
                       "raw_ratio_median": round(em["median"] / fl["median"], 2),
                       "raw_lost": raw_lost + floor_lost, "max_rate": rate}  # fmt: skip
                results["runs"].append(row)
                held = ""
                if rate is not None:
                    held = f"  held {rate['rate_hz']} Hz" if rate["rate_hz"] else "  no rate held"
                print(f"{mode:9s} {placement:8s} N={n:3d} pysoem median "
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
    if args.repeat > 1:
        results["repeated"] = repeated(results["runs"])
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"bench-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    print(f"written {path.relative_to(ROOT)}")
    shutil.rmtree(tmp, ignore_errors=True)  # a run that fails keeps its daemon logs there
    return 0


if __name__ == "__main__":
    from ecatsim.bench_cli import bench

    bench()
