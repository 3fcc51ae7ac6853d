"""Benchmark: the daemon against a real master and against a C echo floor, same run.

    sudo .venv/bin/python tools/bench.py --slaves 1 4 16 --cycles 5000 --period-us 1000

For each N it starts the daemon (N TMC8670 drives) in a private network namespace, brings
the segment to OP with pysoem (DC active) in another, runs cyclic exchange and records the
round trip of each send_processdata()/receive_processdata() pair, lost frames, WKC
mismatches and the daemon's CPU time. The floor is a minimal C responder (compiled here with
the system compiler) that answers the same raw LRW frame; the daemon is timed with the same
raw frame too, so the ratio compares like with like. Results: a table on stdout and JSON in
bench/results/. Ref: docs/performance.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.wire import datagram as dg  # noqa: E402
from tests.integration.netns import Daemon, NetnsPair, in_netns  # noqa: E402

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
    unsigned char buf[2048];
    for (;;) {
        ssize_t n = recv(s, buf, sizeof buf, 0);
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


def pysoem_run(pair: NetnsPair, n: int, cycles: int, period_us: int, pid: int) -> dict[str, Any]:
    import pysoem

    m = pysoem.Master()
    with in_netns(pair.master_ns):
        m.open(pair.master_if)
    try:
        assert m.config_init() == n
        m.config_dc()
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
        rtts, lost, wkc_err = [], 0, 0
        cpu0 = cpu_seconds(pid)
        t_next = time.perf_counter()
        for _ in range(cycles):
            t = time.perf_counter()
            m.send_processdata()
            w = m.receive_processdata(2 * period_us)
            rtts.append(time.perf_counter() - t)
            if w < 0:
                lost += 1
            elif w != m.expected_wkc:
                wkc_err += 1
            t_next += period_us / 1e6
            d = t_next - time.perf_counter()
            if d > 0:
                time.sleep(d)
        cpu = cpu_seconds(pid) - cpu0
        return {"rtt_us": stats(rtts), "lost": lost, "wkc_errors": wkc_err,
                "cpu_per_cycle_us": round(cpu / cycles * 1e6, 1)}  # fmt: skip
    finally:
        m.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slaves", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument("--cycles", type=int, default=5000)
    ap.add_argument("--period-us", type=int, default=1000)
    ap.add_argument("--busy-poll", action="store_true")
    args = ap.parse_args()
    if os.geteuid() != 0:
        print("bench: needs root (namespaces, raw sockets)", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="ecatsim-bench-"))
    echo = tmp / "echo"
    subprocess.run(["cc", "-O2", "-o", str(echo), "-x", "c", "-"], input=ECHO_C.encode(),
                   check=True)  # fmt: skip
    frame = dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, 0, bytes(29))])
    results: dict[str, Any] = {"machine": platform.node(), "cpus": os.cpu_count(),
                               "python": platform.python_version(), "runs": []}  # fmt: skip
    extra = ("--busy-poll",) if args.busy_poll else ()
    for n in args.slaves:
        with NetnsPair() as pair:
            proc = subprocess.Popen(["ip", "netns", "exec", pair.slave_ns, str(echo),
                                     pair.slave_if])  # fmt: skip
            time.sleep(0.2)
            floor, floor_lost = raw_rtt(pair, frame, 2000)
            proc.kill()
            proc.wait()
            d = Daemon(pair, ("--slaves", str(n), *extra), tmp / f"daemon{n}.log")
            d.start(timeout=60)
            try:
                raw, raw_lost = raw_rtt(pair, frame, 2000)
                run = pysoem_run(pair, n, args.cycles, args.period_us, d.pid)
            finally:
                d.stop()
        fl, em = stats(floor), stats(raw)
        row = {
            "slaves": n,
            "floor_rtt_us": fl,
            "raw_rtt_us": em,
            "ratio_median": round(em["median"] / fl["median"], 2),
            "raw_lost": raw_lost + floor_lost,
            **run,
        }
        results["runs"].append(row)
        print(f"N={n:3d} floor {fl['median']:7.1f} us  emulator {em['median']:7.1f} us  "
              f"(x{row['ratio_median']})  pysoem median {run['rtt_us']['median']:7.1f} "
              f"p99 {run['rtt_us']['p99']:7.1f} us  lost {run['lost']} wkc-err "
              f"{run['wkc_errors']}  daemon cpu/cycle {run['cpu_per_cycle_us']} us")  # fmt: skip
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"bench-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.write_text(json.dumps(results, indent=2) + "\n")
    print(f"written {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
