"""Demo master (pysoem) for a segment with a TMC8670 drive and a TMC8460 MFCIO slave
(config/tmc8460-beside-tmc8670.yaml): both to OP in free run; the MFCIO slave, which has no
microcontroller, makes a step/direction move of 2000 steps at 10 kHz that its encoder unit
reads back (4000 counts per turn of a 3200-step motor: 2500 counts), a PWM channel at 30 %,
and no step for a move asked in SAFEOP. The drive stays disabled beside it."""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import pysoem

from ecatsim.mfcio import regs as R
from ecatsim.mfcio.stepdir import sr_for

#: the readable registers in MB1 that the table shows
SHOW = ("SD_SC", "ENC_X", "ENC_LATCH", "IRQ_FLAGS")


def mb0(**values: int) -> bytes:
    out = bytearray(R.MB0_SIZE)
    for name, v in values.items():
        r = R.reg(name)
        assert r.mb is not None
        off = r.mb - R.MB0_START
        out[off : off + r.size] = (v & ((1 << (8 * r.size)) - 1)).to_bytes(r.size, "little")
    return bytes(out)


def mb1(data: bytes) -> dict[str, int]:
    out = {}
    for name in SHOW:
        r = R.reg(name)
        assert r.mb is not None
        off = r.mb - R.MB1_START
        v = int.from_bytes(data[off : off + r.size], "little")
        out[name] = v - (1 << 32) if r.size == 4 and v & 0x80000000 else v
    return out


class Bus:
    def __init__(self, master: Any, mfcio: Any) -> None:
        self.m = master
        self.io = mfcio
        self.values: dict[str, int] = {}
        self.t_next = time.perf_counter()
        self.wkc_errors = 0
        self.cycles = 0
        #: WKC mismatches count outside state changes only (an ESC leaving SAFEOP for INIT
        #: disables its SMs within the cycle that asks, so that cycle's WKC differs)
        self.counting = True

    def cycle(self, n: int = 1, **values: int) -> dict[str, int]:
        self.values.update(values)
        self.io.output = mb0(**self.values)
        for _ in range(n):
            self.m.send_processdata()
            wkc = self.m.receive_processdata(5000)
            self.wkc_errors += self.counting and wkc != self.m.expected_wkc
            self.cycles += 1
            self.t_next += 0.001
            d = self.t_next - time.perf_counter()
            if d > 0:
                time.sleep(d)
        return mb1(bytes(self.io.input))

    def state(self, st: int) -> bool:
        self.m.state = st
        self.m.write_state()
        self.counting = False
        try:
            for _ in range(300):
                self.cycle()
                if self.m.state_check(st, 5000) == st:
                    return True
            return False
        finally:
            self.counting = True


def run(master: Any) -> int:
    """Everything after the master is open; returns the exit code."""
    n = master.config_init()
    if n <= 0:
        print("no slaves found", file=sys.stderr)
        return 1
    for i, s in enumerate(master.slaves):
        print(f"slave {i}: {s.name} vendor 0x{s.man:X} product {s.id} rev 0x{s.rev:08X}")
    mfcio = [s for s in master.slaves if s.id == 8460]
    if not mfcio:
        print("no TMC8460 MFCIO slave (product 8460) in the segment", file=sys.stderr)
        return 1
    io = mfcio[0]
    master.config_map()
    bus = Bus(master, io)
    if not bus.state(pysoem.SAFEOP_STATE) or not bus.state(pysoem.OP_STATE):
        print(f"OP not reached: {[hex(s.al_status) for s in master.slaves]}", file=sys.stderr)
        return 1
    print(
        f"OP: expected WKC {master.expected_wkc}, {len(io.output)} bytes out (MB0), "
        f"{len(io.input)} in (MB1)"
    )
    move = {"ENC_MODE": 0x5C, "ENC_CONST": 0x00010000, "SD_SR": sr_for(10_000), "SD_ST": 2000}
    bus.cycle(2, **move)
    bus.cycle(1, SD_CFG=0x01)
    print(f"step/dir: 2000 steps at 10 kHz (SD_SR {sr_for(10_000)}), encoder 1.0 per count")
    print(f"{'t [ms]':>7} {'SD_SC':>6} {'ENC_X':>6} {'ENC_LATCH':>9} {'IRQ_FLAGS':>9}")
    for k in range(0, 260, 20):
        v = bus.cycle(20)
        print(
            f"{k + 20:7d} {v['SD_SC']:6d} {v['ENC_X']:6d} {v['ENC_LATCH']:9d} {v['IRQ_FLAGS']:#9x}"
        )
    done = bus.cycle(5)
    bus.cycle(
        5,
        PWM_MAXCNT=3999,
        PWM_ALIGNMENT=0b11,
        PWM_CHOPMODE=0x0007,
        PWM_VALUE_0=1200,
        PWM_BBM_H=20,
        PWM_BBM_L=20,
    )
    print("PWM: 25 kHz centred, channel 0 at 30 %, complementary with 200 ns BBM")
    ok = bus.state(pysoem.SAFEOP_STATE)
    bus.cycle(5, SD_CFG=0, SD_ST=1000)
    after = bus.cycle(300, SD_CFG=0x01)
    print(
        f"SAFEOP: a move of 1000 steps asked: SD_SC {done['SD_SC']} -> {after['SD_SC']} "
        "(outputs are taken in OP only)"
    )
    bus.state(pysoem.INIT_STATE)
    print(f"{bus.cycles} cycles, {bus.wkc_errors} WKC errors")
    good = (done["SD_SC"], done["ENC_X"], after["SD_SC"]) == (2000, 2500, 2000)
    return 0 if ok and good and bus.wkc_errors <= bus.cycles // 100 else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iface", default="ecat0")
    args = ap.parse_args()
    master = pysoem.Master()
    master.open(args.iface)
    try:
        return run(master)
    finally:
        master.close()


if __name__ == "__main__":
    sys.exit(main())
