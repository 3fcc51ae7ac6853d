"""Demo master (pysoem): find the drives, bring them to OP, exchange process data, and
print a short table of what came back."""

from __future__ import annotations

import argparse
import struct
import sys
import time

import pysoem

RX = struct.Struct("<HihI")  # 6040 controlword, 607A target position, 6071 torque, 60FF velocity
TX = struct.Struct("<HbihiI")  # 6041, 6061, 6064 position, 6077 torque, 606C velocity, 60FD


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iface", default="ecat0")
    ap.add_argument("--cycles", type=int, default=2000)
    ap.add_argument("--period-us", type=int, default=1000)
    args = ap.parse_args()

    master = pysoem.Master()
    master.open(args.iface)
    try:
        n = master.config_init()
        if n <= 0:
            print("no slaves found", file=sys.stderr)
            return 1
        for i, s in enumerate(master.slaves):
            print(f"slave {i}: {s.name} vendor 0x{s.man:X} product {s.id} rev 0x{s.rev:08X}")
        size = master.config_map()
        if master.state_check(pysoem.SAFEOP_STATE, 2_000_000) != pysoem.SAFEOP_STATE:
            print("SAFEOP not reached", [hex(s.al_status) for s in master.slaves], file=sys.stderr)
            return 1
        master.state = pysoem.OP_STATE
        master.send_processdata()
        master.receive_processdata(2000)
        master.write_state()
        for _ in range(100):
            master.send_processdata()
            master.receive_processdata(2000)
            if master.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
                break
        else:
            print("OP not reached", [hex(s.al_status) for s in master.slaves], file=sys.stderr)
            return 1
        print(f"OP: process image {size} bytes, expected WKC {master.expected_wkc}")
        print(f"{'cycle':>6} {'target':>8} {'actual':>8} {'velocity':>8} {'wkc':>4}")
        bad = 0
        rtts = []
        t_next = time.perf_counter()
        for cycle in range(args.cycles):
            target = cycle * 10
            for s in master.slaves:
                s.output = RX.pack(0x000F, target, 0, 10 * 1000)
            t0 = time.perf_counter()
            master.send_processdata()
            wkc = master.receive_processdata(2000)
            rtts.append(time.perf_counter() - t0)
            bad += wkc != master.expected_wkc
            if cycle % (args.cycles // 10 or 1) == 0:
                _sw, _mode, pos, _tq, vel, _cnt = TX.unpack(bytes(master.slaves[0].input))
                print(f"{cycle:6d} {target:8d} {pos:8d} {vel:8d} {wkc:4d}")
            t_next += args.period_us / 1e6
            delay = t_next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        rtts.sort()
        print(
            f"{args.cycles} cycles, {bad} WKC errors, round trip median "
            f"{rtts[len(rtts) // 2] * 1e6:.0f} us, p99 {rtts[int(len(rtts) * 0.99)] * 1e6:.0f} us"
        )
        master.state = pysoem.INIT_STATE
        master.write_state()
        return 0 if bad == 0 else 1
    finally:
        master.close()


if __name__ == "__main__":
    sys.exit(main())
