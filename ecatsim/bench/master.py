"""The benchmark's master: pysoem brings the segment to OP with DC, every drive enabled in
csp and moving, and the cyclic exchange is timed.

pysoem is imported where a master is made (the bench extra). Ref: CiA 402-2 Figure 5
(the enable sequence), docs/performance.md "How to measure".
"""

from __future__ import annotations

import math
import os
import struct
import time
from pathlib import Path
from typing import Any

from ecatsim.bench.capture import percentile
from ecatsim.bench.netns import NetnsPair, in_netns

#: modes of operation (6060h): cyclic synchronous position
CSP = 8
#: TMC8670 default PDOs (config/tmc8670.yaml): 6040h, 607Ah, 6071h, 60FFh out; 6041h,
#: 6061h, 6064h, 6077h, 606Ch, 60FDh in
RX = struct.Struct("<HihI")
TX = struct.Struct("<HbihiI")
#: the statusword alone, the first field of TX
SW = struct.Struct("<H")


def stats(rtts: list[float]) -> dict[str, float]:
    """Round trips in seconds as min, median, p99, p99.9 and max in microseconds."""
    us = sorted(r * 1e6 for r in rtts)
    return {
        "min": round(us[0], 1),
        "median": round(percentile(us, 0.5), 1),
        "p99": round(percentile(us, 0.99), 1),
        "p999": round(percentile(us, 0.999), 1),
        "max": round(us[-1], 1),
    }


def cpu_seconds(pid: int) -> float:
    """CPU time of process ``pid``, every thread's: the nanoseconds each ran
    (``/proc/PID/task/TID/schedstat``, first field), or, where the kernel keeps no
    schedstat, user + system time in clock ticks (``/proc/PID/stat``, 10 ms: a daemon of a
    few drives runs less than one tick in a short run). Ref: proc(5)."""
    proc = Path(f"/proc/{pid}")
    if not (proc / "schedstat").exists():
        fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    ns = 0
    for task in (proc / "task").iterdir():
        try:
            ns += int((task / "schedstat").read_text().split()[0])
        except FileNotFoundError:
            pass  # the thread ended meanwhile
    return ns / 1e9


def steal_seconds() -> list[float]:
    """Time the hypervisor ran something else on each of this VM's CPUs (steal time,
    the 8th field of each cpuN line of /proc/stat), in seconds; zeros on bare metal."""
    tck = os.sysconf("SC_CLK_TCK")
    return [int(ln.split()[8]) / tck for ln in Path("/proc/stat").read_text().splitlines()
            if ln.startswith("cpu") and ln[3:4].isdigit()]  # fmt: skip


def sender(m: Any, overlap: bool) -> Any:
    """The master's send of the process data: SOEM's overlapped one after
    config_overlap_map (``overlap``; the plain one would send the inputs of the last reply
    back as outputs), else the plain one. ``m``: a pysoem master."""
    return m.send_overlap_processdata if overlap else m.send_processdata


def request_op(m: Any, tries: int, recv_us: int, check_us: int, overlap: bool = False) -> bool:
    """Request OP from SAFEOP as a master does (ETG.1000.6 §6.4: the slaves take OP once
    valid outputs arrive): one exchange, the AL control write, then exchanges until every
    slave reports OP or ``tries`` run out. ``m``: a pysoem master; True if they are in OP."""
    import pysoem

    send = sender(m, overlap)
    m.state = pysoem.OP_STATE
    send()
    m.receive_processdata(recv_us)
    m.write_state()
    for _ in range(tries):
        send()
        m.receive_processdata(recv_us)
        if m.state_check(pysoem.OP_STATE, check_us) == pysoem.OP_STATE:
            break
    return bool(m.read_state() == pysoem.OP_STATE)


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
    if not request_op(m, 500, 50_000, 5000):
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
        #: the cosine's offset (counts) at the last step number asked for: the drives
        #: enabled in the same cycle share it, so it is computed once per cycle, not per drive
        self._x_k = -1
        self._x = 0

    def _offset(self, k: int) -> int:
        """round(x) of the cosine at step ``k``."""
        if k != self._x_k:
            self._x_k = k
            self._x = round(self.AMPLITUDE * (1.0 - math.cos(math.pi * k * self.dt)) / 2.0)
        return self._x

    def outputs(self) -> None:
        """The outputs of every drive from its statusword; the same values per drive as a
        loop that computes each drive's cosine, at a fraction of the master's CPU (its
        work shares the CPUs with the daemon at 128 drives and more)."""
        steps = self.STEPS
        last = len(steps) - 1
        step = self.step
        kk = self.k
        start = self.start
        pack = RX.pack
        sw_of = SW.unpack_from
        for i, s in enumerate(self.m.slaves):
            sw = sw_of(s.input)[0]
            st = step[i]
            cw, mask, want = steps[st]
            if sw & mask == want and st < last:
                st = step[i] = st + 1
                cw = steps[st][0]
            x = 0
            if sw & 0x6F == 0x27:
                k = kk[i] = kk[i] + 1
                x = self._offset(k)
            s.output = pack(cw, start[i] + x, 0, 0)


def cycles(m: Any, seconds: float, period_us: int, pid: int, lock: bool = True,
           spin: bool = False, overlap: bool = False) -> dict[str, Any]:  # fmt: skip
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
    as SOEM's examples do (ec_sync); the echo has no DC clock. With ``spin`` the master
    waits for its next cycle spinning, not in time.sleep(), so its CPU never halts between
    cycles (a halted vCPU can be slow to come back on a VM)."""
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
    send = sender(m, overlap)
    done, behind = 0, False
    for _ in range(n):
        if time.perf_counter() - t_next > 1.0:
            behind = True  # a whole second behind the schedule: this rate is not kept
            break
        done += 1
        motion.outputs()
        t = time.perf_counter()
        send()
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
        if spin:
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
