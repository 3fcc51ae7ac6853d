"""Demo master (pysoem): find the drives, start distributed clocks (SYNC0 every cycle), bring
them to OP, enable the CiA 402 drive, make a profile-position move and then follow a sine in
cyclic synchronous position mode, and print short tables of what came back."""

from __future__ import annotations

import argparse
import gc
import math
import os
import struct
import sys
import time

import pysoem

RX = struct.Struct("<HihI")  # 6040 controlword, 607A target position, 6071 torque, 60FF velocity
TX = struct.Struct("<HbihiI")  # 6041, 6061, 6064 position, 6077 torque, 606C velocity, 60FD
PP, CSP = 1, 8


class Bus:
    def __init__(self, master: pysoem.Master, period_us: int) -> None:
        self.m = master
        self.period = period_us / 1e6
        self.t_next = time.perf_counter()
        self.rtts: list[float] = []
        self.wkc_errors = 0
        self.cycles = 0
        #: system time of the first SYNC0 pulse: the cycle is kept mid-way between pulses
        self.sync0_start: int | None = None

    def cycle(self, cw: int, pos: int = 0, vel: int = 0) -> tuple[int, ...]:
        for s in self.m.slaves:
            s.output = RX.pack(cw, pos, 0, vel & 0xFFFFFFFF)
        t0 = time.perf_counter()
        self.m.send_processdata()
        wkc = self.m.receive_processdata(5000)
        self.rtts.append(time.perf_counter() - t0)
        self.wkc_errors += wkc != self.m.expected_wkc
        self.cycles += 1
        self.t_next += self.period
        if self.sync0_start is not None:  # as SOEM's examples do (ec_sync): stay mid-cycle
            cycle_ns = round(self.period * 1e9)
            phase = (self.m.dc_time - self.sync0_start) % cycle_ns
            self.t_next += 0.1 * (cycle_ns / 2 - phase) / 1e9
        delay = self.t_next - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        return TX.unpack(bytes(self.m.slaves[0].input))


def to_op(master: pysoem.Master, bus: Bus) -> None:
    master.config_map()
    if master.state_check(pysoem.SAFEOP_STATE, 2_000_000) != pysoem.SAFEOP_STATE:
        raise SystemExit(f"SAFEOP not reached: {[hex(s.al_status) for s in master.slaves]}")
    master.state = pysoem.OP_STATE
    bus.cycle(0)
    master.write_state()
    for _ in range(200):
        bus.cycle(0)
        if master.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
            return
    raise SystemExit(f"OP not reached: {[hex(s.al_status) for s in master.slaves]}")


def enable(bus: Bus, pos: int = 0) -> None:
    for cw in (0x00, 0x06, 0x07, 0x0F):
        for _ in range(5):
            sw = bus.cycle(cw, pos)[0]
    if sw & 0x6F != 0x27:
        raise SystemExit(f"drive not enabled: statusword 0x{sw:04X}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iface", default="ecat0")
    ap.add_argument("--period-us", type=int, default=1000)
    ap.add_argument("--target", type=int, default=50_000, help="pp target (encoder counts)")
    ap.add_argument("--amplitude", type=int, default=20_000, help="csp sine (counts)")
    args = ap.parse_args()

    if os.geteuid() == 0:  # a real-time master, below the daemon's --rt-priority 40
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(30))
    gc.disable()  # no collector pause in the cycle
    master = pysoem.Master()
    master.open(args.iface)
    try:
        n = master.config_init()
        if n <= 0:
            print("no slaves found", file=sys.stderr)
            return 1
        for i, s in enumerate(master.slaves):
            print(f"slave {i}: {s.name} vendor 0x{s.man:X} product {s.id} rev 0x{s.rev:08X}")
        for s in master.slaves:
            s.sdo_write(0x6060, 0, struct.pack("<b", PP))
            s.sdo_write(0x6081, 0, struct.pack("<I", 1000))  # profile velocity, rpm
            s.sdo_write(0x6083, 0, struct.pack("<I", 4000))  # acceleration, rpm/s
            s.sdo_write(0x6084, 0, struct.pack("<I", 4000))
        master.config_dc()
        for s in master.slaves:
            s.dc_sync(True, args.period_us * 1000)
        bus = Bus(master, args.period_us)
        to_op(master, bus)
        for _ in range(150):  # SOEM starts SYNC0 100 ms after dc_sync
            bus.cycle(0)
        bus.sync0_start = struct.unpack("<Q", master.slaves[0]._fprd(0x0990, 8))[0]
        print(f"OP: expected WKC {master.expected_wkc}; pp move to {args.target} counts")
        enable(bus, args.target)
        print(f"{'t [ms]':>7} {'statusword':>10} {'position':>9} {'velocity':>9}")
        bus.cycle(0x1F, args.target)  # new set point
        t0 = bus.cycles
        for i in range(5000):
            sw, _mode, pos, _tq, vel, _di = bus.cycle(0x1F, args.target)
            if i % 100 == 0:
                print(f"{bus.cycles - t0:7d} {sw:#10x} {pos:9d} {vel:9d}")
            if sw & 0x0400 and i > 10:
                print(f"{bus.cycles - t0:7d} {sw:#10x} {pos:9d} {vel:9d}  target reached")
                break
        # csp: a sine around where the move ended, one target per SYNC0
        for s in master.slaves:  # mode switch over SDO while enabled
            s.sdo_write(0x6060, 0, struct.pack("<b", CSP))
        amplitude, freq = args.amplitude, 1.0
        centre = bus.cycle(0x0F, pos)[2]
        print(f"csp: two turns of a {amplitude}-count cosine at {freq:g} Hz, DC SYNC0 every cycle")
        print(f"{'t [ms]':>7} {'target':>9} {'position':>9} {'velocity':>9} {'error':>6}")
        n = int(2.0 / (args.period_us / 1e6))
        worst = 0
        for k in range(n + 1):
            t_s = k * args.period_us / 1e6
            # from rest to rest: the demand starts and ends with zero velocity
            target = centre + round(amplitude * (1 - math.cos(2 * math.pi * freq * t_s)))
            sw, _m, pos, _t, vel, _d = bus.cycle(0x0F, target)
            if k > 20:
                worst = max(worst, abs(target - pos))
            if k % 250 == 0:
                err = target - pos
                print(f"{round(t_s * 1000):7d} {target:9d} {pos:9d} {vel:9d} {err:6d}")
        print(f"csp: largest distance to the newest target {worst} counts")
        for _ in range(50):
            bus.cycle(0x0F, centre)
        bus.cycle(0x06, centre)  # shut down where it stands
        rtts = sorted(bus.rtts)
        print(
            f"{bus.cycles} cycles, {bus.wkc_errors} WKC errors, round trip median "
            f"{rtts[len(rtts) // 2] * 1e6:.0f} us, p99 {rtts[int(len(rtts) * 0.99)] * 1e6:.0f} us"
        )
        master.state = pysoem.INIT_STATE
        master.write_state()
        return 0 if bus.wkc_errors <= bus.cycles // 100 else 1  # a loaded host may lose a few
    finally:
        master.close()


if __name__ == "__main__":
    sys.exit(main())
