"""The TMC8670 drive moved by a real master through the datasheet examples (§7.3, §8.2, §9.2),
statusword asserted after each step. Free run: outputs act when SM2 is written.
Ref: TMC8670 §6-§9; CiA 402-2.
"""

from __future__ import annotations

import dataclasses
import gc
import itertools
import json
import os
import struct
import time
from typing import Any

import pysoem
import pytest

from ecatsim.ethercat import daemon as daemon_mod
from tests.integration.test_esc_master import RX_TIMEOUT_US, to_op
from tests.support.compiled import require_built
from tests.support.stall import StallWatch, stalled

pytestmark = pytest.mark.integration

RX = struct.Struct("<HihI")  # 6040, 607A, 6071, 60FF
TX = struct.Struct("<HbihiI")  # 6041, 6061, 6064, 6077, 606C, 60FD
KT, J = 0.05, 2.0e-5  # default motor: torque constant (Nm/A) and inertia (kg m^2)


class Cycle:
    def __init__(self, master: Any) -> None:
        self.m = master
        self.s = master.slaves[0]
        self.t_next = time.perf_counter()

    def run(self, cw: int, pos: int = 0, torque: int = 0, vel: int = 0) -> tuple[int, ...]:
        self.s.output = RX.pack(cw, pos, torque, vel)
        self.m.send_processdata()
        assert self.m.receive_processdata(RX_TIMEOUT_US) == 3
        self.t_next += 0.001
        d = self.t_next - time.perf_counter()
        if d > 0:
            time.sleep(d)
        return TX.unpack(bytes(self.s.input))


def start(master_factory: Any, daemon_factory: Any, mode: int, **sdo: int | bytes) -> Cycle:
    daemon_factory()
    m = master_factory()
    assert m.config_init() == 1
    s = m.slaves[0]
    s.sdo_write(0x6060, 0, struct.pack("<b", mode))
    for name, value in sdo.items():
        index = int(name[1:], 16)
        if isinstance(value, bytes):
            s.sdo_write(index, 0, value)
        else:
            s.sdo_write(index, 0, struct.pack("<I" if value >= 0 else "<i", value))
    to_op(m)
    return Cycle(m)


#: (controlword, statusword mask, expected statusword) of the enable sequence
ENABLE_STEPS = ((0x00, 0x4F, 0x40), (0x06, 0x6F, 0x21), (0x07, 0x6F, 0x23), (0x0F, 0x6F, 0x27))


def enable(c: Cycle, **kw: int) -> None:
    """Controlword 6, 7, 15 as in the examples; the statusword checked after each step. A
    step may take a few cycles (with DC a command acts at the next SYNC0 and shows at the
    one after), so each waits up to 50 cycles, as a master does."""
    for cw, mask, want in ENABLE_STEPS:
        for _ in range(50):
            sw = c.run(cw, **kw)[0]
            if sw & mask == want:
                break
        assert sw & mask == want, f"controlword 0x{cw:02X}: statusword 0x{sw:04X}"
    assert sw & 0x0210 == 0x0210  # remote, voltage enabled


def test_pp_example_target_50000(master_factory: Any, daemon_factory: Any) -> None:
    c = start(master_factory, daemon_factory, 1, x6081=500, x6083=2000, x6084=2000)
    enable(c, pos=50_000)
    sw = c.run(0x1F, pos=50_000)[0]  # new set point (bit 4)
    peak = 0
    for _ in range(4000):
        sw, mode, pos, _tq, vel, _di = c.run(0x1F, pos=50_000)
        peak = max(peak, abs(vel))
        if sw & 0x0400:
            break
    assert mode == 1
    assert sw & 0x0400, "target not reached"
    assert abs(pos - 50_000) <= 20
    assert abs(peak - 500) <= 10  # within 2 % of 6081


def test_pv_example_2000_rpm(master_factory: Any, daemon_factory: Any) -> None:
    c = start(master_factory, daemon_factory, 3, x6083=2000, x6084=2000)
    enable(c)
    t0 = time.perf_counter()
    reached = None
    for _i in range(3000):
        sw, _m, _p, _t, vel, _d = c.run(0x0F, vel=2000)
        if sw & 0x0400 and vel > 1900 and reached is None:
            reached = time.perf_counter() - t0
            break
    assert reached is not None
    assert 0.9 <= reached <= 1.6  # ramp 2000 rpm at 2000 rpm/s: 1 s (+ loop settling)
    for _ in range(1500):  # stop by writing 0 to 60FF
        sw, _m, _p, _t, vel, _d = c.run(0x0F, vel=0)
        if abs(vel) < 1 and sw & 0x1000:
            break
    assert abs(vel) < 1


def test_cst_example_torque_step(master_factory: Any, daemon_factory: Any) -> None:
    """§9.2: a torque step; the acceleration is the torque over the inertia, within 5 % of
    the friction-free value. The step is 3 A (150 mNm): the default Coulomb friction (2 mNm)
    takes 1.3 %, the viscous friction B*w grows as B/J * t, so the fit uses the first 60 ms
    after the current loop settled (about 2 % on average)."""
    torque_ma = 3000
    c = start(master_factory, daemon_factory, 10)
    enable(c)
    samples = []
    for _ in range(80):
        t_send = time.perf_counter()
        _sw, _m, _p, torque, vel, _d = c.run(0x0F, torque=torque_ma)
        samples.append((t_send, vel))
    assert abs(torque - torque_ma) <= 5  # 6077h follows within the current loop's accuracy
    # acceleration: least-squares slope of velocity over time (rpm/s -> rad/s^2); the fit
    # averages out the master's own timing jitter
    pts = samples[20:]
    t_mean = sum(t for t, _ in pts) / len(pts)
    v_mean = sum(v for _, v in pts) / len(pts)
    slope = sum((t - t_mean) * (v - v_mean) for t, v in pts) / sum(
        (t - t_mean) ** 2 for t, _ in pts
    )
    accel = slope * 2 * 3.141592653589793 / 60
    ideal = KT * torque_ma / 1000 / J  # friction free: Kt * I / J
    assert 0.95 * ideal <= accel <= 1.02 * ideal, accel / ideal


@dataclasses.dataclass
class SineRun:
    """One csp sine run: the master, the daemon and what the master saw."""

    m: Any
    d: Any
    rows: list[tuple[int, ...]]
    errors: list[int]
    judged: list[tuple[int, float, int]]  # (error, bound, cycle)
    anomalies: list[int]
    k: int
    bound: float
    max_gap_s: float  # the longest the master itself went between two cycles

    def left_op_enabled(self) -> bool:
        return not all(r[0] & 0x6F == 0x27 for r in self.rows)

    def why(self) -> str:
        """The drives' statuswords, AL status and code, and the daemon's warnings."""
        al = [
            (hex(s._fprd(0x0130, 2)[0]), hex(struct.unpack("<H", s._fprd(0x0134, 2))[0]))
            for s in self.m.slaves
        ]
        warnings = [ln for ln in self.d.log.read_text().splitlines() if '"warning"' in ln]
        return (
            f"statuswords {[hex(r[0]) for r in self.rows]}, AL status/code {al}, longest "
            f"master cycle gap {self.max_gap_s * 1e3:.1f} ms, daemon warnings {warnings[-5:]}"
        )


def _csp_sine(master_factory: Any, daemon_factory: Any, cfg: Any, started: list[Any]) -> SineRun:
    """The scenario of :func:`test_csp_sine_with_dc_sync0` up to the end of the sine (the
    daemon and the master are added to ``started`` as they start)."""
    import math

    d = daemon_factory("--config", str(cfg), "--rt-priority", "40")
    started.append(d)
    m = master_factory()
    started.append(m)
    assert m.config_init() == 2
    for s in m.slaves:
        s.sdo_write(0x6060, 0, struct.pack("<b", 8))
        s.sdo_write(0x1A00, 0, b"\x00")
        s.sdo_write(0x1A00, 6, struct.pack("<I", 0x60F40020))  # following error actual
        s.sdo_write(0x1A00, 0, b"\x06")
    assert m.config_dc()
    for s in m.slaves:
        s.dc_sync(True, 1_000_000)
    to_op(m)
    for s in m.slaves:
        assert s._fprd(0x0981, 1)[0] & 0x03 == 0x03  # SYNC unit and SYNC0 active
    c = Cycle(m)

    sync0_start = struct.unpack("<Q", m.slaves[0]._fprd(0x0990, 8))[0]
    last_send = [time.perf_counter(), 0.0]  # [time of the last send, longest gap]

    def sync0_phase() -> int:
        """Where in the SYNC0 cycle the last frame passed the reference clock (ns)."""
        return int((m.dc_time - sync0_start) % 1_000_000)

    def all_cycle(cw: int, pos: int) -> list[tuple[int, ...]]:
        for s in m.slaves:
            s.output = RX.pack(cw, pos, 0, 0)
        now = time.perf_counter()
        last_send[1] = max(last_send[1], now - last_send[0])
        last_send[0] = now
        m.send_processdata()
        assert m.receive_processdata(RX_TIMEOUT_US) == 6
        # keep the frames mid-cycle between SYNC0 pulses, as SOEM's examples do (ec_sync)
        c.t_next += 0.001 + 0.1 * (500_000 - sync0_phase()) / 1e9
        d = c.t_next - time.perf_counter()
        if d > 0:
            time.sleep(d)
        return [TX.unpack(bytes(s.input)) for s in m.slaves]

    for _ in range(200):  # SOEM starts SYNC0 100 ms after dc_sync: let it run first
        all_cycle(0x00, 0)
    assert m.slaves[0]._fprd(0x0984, 1)[0] & 0x01 == 0  # first SYNC0 no longer pending
    for cw, mask, want in ENABLE_STEPS:
        for _ in range(50):
            rows = all_cycle(cw, 0)
            if all(r[0] & mask == want for r in rows):
                break
        assert all(r[0] & mask == want for r in rows), (cw, [hex(r[0]) for r in rows])
    amplitude, freq = 20_000, 0.5  # counts, Hz
    # bound: with velocity feed-forward the error is about a_max / (w_pos * w_vel)
    a_max = (2 * math.pi * freq) ** 2 * amplitude  # counts/s^2
    w_pos = 0.7 * 4096 / 60  # 1/s, default position gain 0.7 rpm/count, 4096 counts/rev
    w_vel = 0.05 * (12.5e-3 / (2 * math.pi / 60)) / 2.0e-5  # rad/s, Kt * Kv / J
    v_max = 2 * math.pi * freq * amplitude  # counts/s
    # the demand is a staircase (one target per SYNC0): +- v_max * T_cycle on top
    bound = 4 * a_max / (w_pos * w_vel) + v_max * 0.001 + 5
    step = v_max * 0.001  # one demand step
    # A real-time master, as on a real machine, below the daemon (--rt-priority 40): SOEM
    # spins while it waits for the reply and must not hold off the daemon sending it.
    old_policy, old_param = os.sched_getscheduler(0), os.sched_getparam(0)
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(30))
    errors: list[int] = []
    # The bound assumes one new target per SYNC0. When the master itself stalls or bursts
    # (seen in the DC time of its frames: a SYNC0 interval with no frame, or two), the
    # demand jumps, on real drives too. Each such interval in the last 150 cycles (7
    # position-loop time constants) adds one demand step to the bound; cycles with more
    # than 5 of them are not judged.
    judged: list[tuple[int, float, int]] = []
    anomalies: list[int] = []
    window, max_anomalies = 150, 5
    interval_prev = (m.dc_time - sync0_start) // 1_000_000
    last_send[1] = 0.0  # the gaps of the sine itself
    try:
        k = 0
        # 5 s of sine, longer (up to 30 s) until 1000 cycles could be judged; at least 500
        # must be (a host too busy for that cannot hold a 1 ms master cycle at all)
        while k < 5000 or (len(judged) < 1000 and k < 30_000):
            k += 1
            target = round(amplitude * math.sin(2 * math.pi * freq * k / 1000))
            rows = all_cycle(0x0F, target)
            err = max(abs(r[5] if r[5] < 2**31 else r[5] - 2**32) for r in rows)
            interval = (m.dc_time - sync0_start) // 1_000_000
            anomalies.append(abs(interval - interval_prev - 1))
            interval_prev = interval
            if k > 50:
                errors.append(err)
            recent = sum(anomalies[-window:])
            if k > window and recent <= max_anomalies:
                judged.append((err, bound + step * recent, k))
            if rows[0][0] & 0x6F != 0x27 or rows[1][0] & 0x6F != 0x27:
                break  # no longer following: nothing more to judge
    finally:
        os.sched_setscheduler(0, old_policy, old_param)
    return SineRun(m, d, rows, errors, judged, anomalies, k, bound, last_send[1])


def test_csp_sine_with_dc_sync0(master_factory: Any, daemon_factory: Any, tmp_path: Any) -> None:
    """config_dc, SYNC0 at 1 ms, csp following a sine for 5 s on two drives (the second
    with a drifting clock), the master's frames kept mid-cycle from the DC time as SOEM's
    examples do. The drives stay in Operation enabled; the following error (60F4h, mapped
    instead of 60FDh) stays within a bound from the loop gains, plus one demand step for
    each SYNC0 interval of the last 150 in which the master did not deliver exactly one
    target; the DC time difference (0x092C) converges below 1 us. Master and daemon run
    SCHED_FIFO, as real-time masters do.

    A host that stops everything (master, daemon and a watch above both) for 50 ms or more
    takes the drives out of OP or loses a reply, as it would stopping a real master: only
    then, with the stall measured by the watch, the run is repeated (at most three runs)."""
    cfg = tmp_path / "seg.yaml"
    cfg.write_text("slaves:\n  - device: tmc8670\n  - device: tmc8670\n    dc_drift_ppm: 25\n")
    stalls: list[str] = []
    for _ in range(3):
        started: list[Any] = []
        failure = ""
        # No collector pause in the master's cycle: after a long test session a full
        # collection takes about as long as the SM watchdog (100 ms), so it runs before the
        # cyclic exchange begins, and not again until the run is over.
        gc.collect()
        gc.disable()
        with StallWatch() as watch:
            try:
                run = _csp_sine(master_factory, daemon_factory, cfg, started)
                if run.left_op_enabled():
                    failure = f"the drives left Operation enabled: {run.why()}"
            except AssertionError as exc:
                failure = f"{exc!r}"
            finally:
                gc.enable()
        if not failure:
            break
        if not stalled(watch.worst_s):
            pytest.fail(f"{failure} (no host stall: {watch.worst_s * 1e3:.1f} ms)")
        stalls.append(f"{failure} (the host stalled {watch.worst_s * 1e3:.0f} ms)")
        for part in reversed(started):
            part.close() if hasattr(part, "close") else part.stop()
    else:
        pytest.fail(f"the host stalled in each of 3 runs: {stalls}")
    m, d, k, bound = run.m, run.d, run.k, run.bound
    ranked = sorted(run.errors)
    assert ranked[len(ranked) // 2] <= bound, (bound, ranked[-10:])
    judged, anomalies = run.judged, run.anomalies
    assert len(judged) >= 500, (
        f"the master met its schedule in only {len(judged)} of {k} cycles "
        f"({sum(1 for a in anomalies if a)} SYNC0 intervals without exactly one frame)"
    )
    over = [(e, round(b), f"cycle {c}", anomalies[c - 10 : c]) for e, b, c in judged if e > b]
    assert not over, (len(judged), over[:10])
    diff = struct.unpack("<I", m.slaves[1]._fprd(0x092C, 4))[0] & 0x7FFFFFFF
    assert diff < 1000  # ns
    # the cyclic frames were answered by the compiled responder (decision P9), if built:
    # nearly all of the k judged ones
    assert d.stop() == 0
    stopped = [json.loads(ln) for ln in d.log.read_text().splitlines() if '"stopped"' in ln]
    require_built(daemon_mod.responder, "ecatsim.ethercat.responder")
    assert stopped[-1]["compiled_replies"] >= 0.9 * k, (k, stopped[-1])


def test_overcurrent_emcy_quick_stop_and_fault_reset(
    master_factory: Any, daemon_factory: Any, tmp_path: Any
) -> None:
    """An injected overcurrent (control socket) faults the drive with an EMCY that pysoem
    receives; a fault reset recovers once the cause is gone; quick stop uses 6085h."""
    from ecatsim.ctl.server import request
    from tests.integration.test_faults import ctl_slave

    sock, m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    emcys: list[Any] = []
    s.add_emergency_callback(emcys.append)
    s.sdo_write(0x6060, 0, struct.pack("<b", 3))
    s.sdo_write(0x6085, 0, struct.pack("<I", 5000))
    s.sdo_write(0x6083, 0, struct.pack("<I", 10000))
    assert oct(sock.stat().st_mode & 0o777) == "0o600"
    to_op(m)
    c = Cycle(m)
    enable(c)
    for _ in range(300):
        c.run(0x0F, vel=1000)
    # quick stop: 1000 rpm at 5000 rpm/s takes 200 ms, then switch on disabled (605Ah = 2)
    n = 0
    while True:
        sw, _m, _p, _t, vel, _d = c.run(0x0B, vel=1000)
        n += 1
        if sw & 0x6F == 0x40 or n > 400:
            break
    assert 170 <= n <= 260, n
    assert abs(vel) < 5
    enable(c)
    assert request(sock, {"cmd": "fault", "slave": 0, "kind": "overcurrent"})["ok"]
    for _ in range(50):
        sw = c.run(0x0F)[0]
        m.slaves[0].mbx_receive()
        if sw & 0x4F == 0x08 and emcys:
            break
    assert sw & 0x4F == 0x08  # fault
    assert emcys and emcys[0].error_code == 0x2310
    assert struct.unpack("<H", s.sdo_read(0x603F, 0))[0] == 0x2310
    assert s.sdo_read(0x1001, 0)[0] & 0x03 == 0x03  # generic + current
    for _ in range(3):
        sw = c.run(0x80)[0]
    assert sw & 0x4F == 0x08  # cause still present: no reset
    assert request(sock, {"cmd": "fault", "slave": 0, "kind": "overcurrent", "active": False})["ok"]
    for cw in (0x00, 0x80):
        for _ in range(3):
            sw = c.run(cw)[0]
    assert sw & 0x4F == 0x40  # fault reset -> switch on disabled
    assert struct.unpack("<H", s.sdo_read(0x603F, 0))[0] == 0


def test_homing_on_index_pulse_then_current_position(
    master_factory: Any, daemon_factory: Any
) -> None:
    """hm: method 34 runs to the index pulse and sets 607Ch there, then holds."""
    c = start(master_factory, daemon_factory, 6, x6098=b"\x22", x607C=1000)
    enable(c)
    for _ in range(3):
        c.run(0x0F)
    attained = False
    for _ in range(3000):
        sw, mode, pos, _t, _v, _d = c.run(0x1F)  # bit 4: homing operation start
        if sw & 0x1400 == 0x1400:
            attained = True
            break
    assert mode == 6 and attained
    for _ in range(200):
        sw, _m, pos, _t, vel, _d = c.run(0x1F)
    assert abs(pos - 1000) <= 40 and abs(vel) < 5  # home offset at the index, stopped there


def test_index_pulse_latched_and_sync1(master_factory: Any, daemon_factory: Any) -> None:
    """The encoder index pulse drives LATCH1 (0x09A8-0x09CF): at 600 rpm it comes every
    100 ms, and the latched system times say so. SYNC1 follows SYNC0 by its cycle time
    (SOEM's dc_sync01). Ref: TMC8460 §5.50.4-5.50.5; decisions D14, DC5."""
    daemon_factory()
    m = master_factory()
    assert m.config_init() == 1
    s = m.slaves[0]
    s.sdo_write(0x6060, 0, struct.pack("<b", 3))
    s.sdo_write(0x6083, 0, struct.pack("<I", 6000))
    assert m.config_dc()
    s.dc_sync(True, 1_000_000, 0, 250_000)
    to_op(m)
    assert s._fprd(0x0981, 1)[0] == 0x07  # SYNC unit, SYNC0, SYNC1
    c = Cycle(m)
    for _ in range(200):  # SOEM starts SYNC0 100 ms after dc_sync
        c.run(0x00)
    enable(c)
    for _ in range(400):
        vel = c.run(0x0F, vel=600)[4]
    assert abs(vel - 600) <= 5
    s._fpwr(0x09A9, b"\x00")  # LATCH1: continuous on both edges
    times = []
    for _ in range(8):  # 320 ms: at least 3 turns
        for _ in range(40):
            c.run(0x0F, vel=600)
        times.append(struct.unpack("<Q", s._fprd(0x09C0, 8))[0])
    distinct = sorted(set(times))
    assert len(distinct) >= 3, times
    for a, b in itertools.pairwise(distinct):
        revs = (b - a) / 100e6
        assert abs(revs - round(revs)) < 0.01 and round(revs) >= 1, (a, b)  # 100 ms a turn
    # single event: the first edge is kept until the time is read
    s._fpwr(0x09A9, b"\x01")
    for _ in range(150):
        c.run(0x0F, vel=600)
    status = s._fprd(0x09AF, 1)[0]
    assert status & 0x01
    first = struct.unpack("<Q", s._fprd(0x09C0, 8))[0]
    assert s._fprd(0x09AF, 1)[0] & 0x01 == 0  # read out: cleared
    assert first > distinct[-1]
    # SYNC1: 250 us after each SYNC0
    next0 = struct.unpack("<Q", s._fprd(0x0990, 8))[0]
    next1 = struct.unpack("<Q", s._fprd(0x0998, 8))[0]
    assert (next1 - next0) % 1_000_000 == 250_000
    assert s._fprd(0x098F, 1)[0] & 0x01  # SYNC1 has fired


def test_master_stops_cycling_watchdog_stops_the_motor(
    master_factory: Any, daemon_factory: Any
) -> None:
    """Loss of the master in OP (TMC8670 §3.2): the process-data watchdog expires, the
    slave leaves OP with 0x001B, the drive drops to switch on disabled and the motor runs
    down to standstill (watched in the inputs the master reads again in SAFEOP)."""
    c = start(master_factory, daemon_factory, 3, x6083=10000)
    m, s = c.m, c.s
    enable(c)
    for _ in range(300):
        vel = c.run(0x0F, vel=1000)[4]
    assert abs(vel - 1000) <= 10
    time.sleep(0.25)  # the master is gone for 2.5x the 100 ms watchdog
    m.read_state()
    assert s.state == pysoem.SAFEOP_STATE | pysoem.STATE_ERROR
    assert s.al_status == 0x001B
    speeds = []
    for _ in range(3000):
        m.send_processdata()
        m.receive_processdata(RX_TIMEOUT_US)
        sw, _m, _p, _t, vel, _d = TX.unpack(bytes(s.input))
        speeds.append(vel)
        if vel == 0:
            break
        time.sleep(0.001)
    assert sw & 0x4F == 0x40  # switch on disabled: no torque
    assert speeds[-1] == 0, speeds[-5:]  # at standstill
    assert all(b <= a for a, b in itertools.pairwise(speeds))  # slowing down all the way


@pytest.mark.parametrize(
    ("kind", "code"),
    [("following_error", 0x8611), ("encoder_loss", 0x7305), ("overtemperature", 0x4310)],
)
def test_drive_faults_emcy_and_reset(
    master_factory: Any, daemon_factory: Any, tmp_path: Any, kind: str, code: int
) -> None:
    """Each drive fault injected at run time: fault reaction, fault, 603Fh, an EMCY pysoem
    receives; fault reset recovers once the cause is cleared. Ref: issue "drive" (faults)."""
    from ecatsim.ctl.server import request
    from tests.integration.test_faults import ctl_slave

    sock, m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    emcys: list[Any] = []
    s.add_emergency_callback(emcys.append)
    s.sdo_write(0x6060, 0, struct.pack("<b", 3))
    to_op(m)
    c = Cycle(m)
    enable(c)
    reply = request(sock, {"cmd": "inject", "fault": {"kind": kind, "slave": 0}})
    assert reply["ok"], reply
    for _ in range(100):
        sw = c.run(0x0F)[0]
        s.mbx_receive()
        if sw & 0x4F == 0x08 and emcys:
            break
    assert sw & 0x4F == 0x08  # fault
    assert [e.error_code for e in emcys] == [code]
    assert struct.unpack("<H", s.sdo_read(0x603F, 0))[0] == code
    assert request(sock, {"cmd": "clear", "id": reply["id"]})["cleared"] == 1
    for cw in (0x00, 0x80):
        for _ in range(3):
            sw = c.run(cw)[0]
    assert sw & 0x4F == 0x40  # fault reset -> switch on disabled
