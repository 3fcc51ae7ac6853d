"""One DC cycle in process, for profilers: N enabled TMC8670 drives in csp, SYNC0 every 1 ms,
one cyclic frame (LRW over the process image + FRMW of the DC system time, as SOEM sends)
mid-way between pulses, served by the daemon loop (`Daemon.handle_one` and its timers) on a
loopback link with a manual clock.

    .venv/bin/python tools/cycle_profile.py --drives 1 --cycles 2000          # us per cycle
    .venv/bin/python tools/cycle_profile.py --drives 16 --profile | head -40  # cProfile
    tools/icount.sh 1 --idle       # instructions per cycle (callgrind, two run lengths)

Ref: docs/performance.md.
"""

from __future__ import annotations

import argparse
import cProfile
import math
import pstats
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.daemon import Daemon  # noqa: E402
from ecatsim.link.loopback import LoopbackLink  # noqa: E402
from ecatsim.wire import datagram as dg  # noqa: E402
from tests.perf.hotpath import configure_to_op  # noqa: E402
from tests.support.tinymaster import TinyMaster, segment_of  # noqa: E402

MS = 1_000_000
OUT, IN = 12, 17  # TMC8670 default PDOs (config/tmc8670.yaml)
CSP = 8


class CspCycle:
    """N drives in OP, enabled in csp, SYNC0 at 1 ms; ``step()`` runs one cycle."""

    def __init__(self, drives: int, device: str = "tmc8670", enable: bool = True) -> None:
        self.n = drives
        self.seg, self.clock = segment_of(drives, device=device)
        t = TinyMaster(self.seg)
        configure_to_op(t, drives)
        self.link = LoopbackLink()
        self.daemon = Daemon(self.link, self.seg)
        self.buf = bytearray(2048)
        for fw in self.seg.firmware:
            coe = getattr(fw, "coe", None)
            if coe is not None:
                coe.od.set(0x6060, 0, CSP)
        ref = struct.unpack("<Q", t.aprd(0, 0x0910, 8).data)[0]
        start = ref + 2 * MS
        for pos in range(drives):  # system time offsets as SOEM's config_dc writes them
            local = struct.unpack("<Q", t.aprd(pos, 0x0910, 8).data)[0]
            t.apwr(pos, 0x0920, struct.pack("<Q", (ref - local) & (2**64 - 1)))
            t.apwr(pos, 0x09A0, struct.pack("<I", MS))
            t.apwr(pos, 0x0990, struct.pack("<Q", start))
            t.apwr(pos, 0x0981, b"\x03")
        t0 = self.seg.escs[0].dc.sync0_deadline()
        assert t0 is not None
        self.t = t0
        self.k = 0
        self.target = 0
        self.cw = 0x0F if enable else 0x00
        for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F) if enable else ():
            self.step(cw)  # shutdown, switch on, enable operation

    def frame(self, cw: int) -> bytes:
        out = b"".join(struct.pack("<HiHi", cw, self.target, 0, 0) for _ in range(self.n))
        return dg.ethernet_frame(
            [
                dg.build_logical(dg.Cmd.LRW, 0, out + bytes(IN * self.n), more=True),
                dg.build(dg.Cmd.FRMW, 0x1000, 0x0910, bytes(8)),
            ]
        )

    def step(self, cw: int | None = None) -> None:
        self.clock.t = self.t
        self.clock.t = self.t + 20_000  # the timer wakes a little late, as poll(2) does
        self.daemon._service_timers()  # SYNC0
        self.clock.t = self.t + MS // 2
        self.target = int(20_000 * (1 - math.cos(self.k * 2e-3 * math.pi)))
        self.link.master_send(self.frame(self.cw if cw is None else cw))
        self.link.rx_ns = self.clock.t
        self.daemon.handle_one(self.buf)
        reply = self.link.master_recv()
        assert reply is not None
        self.t += MS
        self.k += 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=1)
    ap.add_argument("--cycles", type=int, default=2000)
    ap.add_argument("--device", default="tmc8670", help="tmc8670 | echo")
    ap.add_argument("--idle", action="store_true", help="drives in OP but not enabled")
    ap.add_argument("--profile", action="store_true", help="cProfile, sorted by own time")
    args = ap.parse_args()
    c = CspCycle(args.drives, args.device, enable=not args.idle)
    for _ in range(100):  # warm up
        c.step()
    if args.profile:
        prof = cProfile.Profile()
        prof.runcall(lambda: [c.step() for _ in range(args.cycles)])
        pstats.Stats(prof).sort_stats("tottime").print_stats(30)
        return 0
    t = time.perf_counter()
    for _ in range(args.cycles):
        c.step()
    us = (time.perf_counter() - t) / args.cycles * 1e6
    coe = getattr(c.seg.firmware[0], "coe", None)
    st = f" statusword {coe.od.value(0x6041):#06x}" if coe is not None else ""
    print(f"{args.drives} x {args.device}: {us:.1f} us per cycle{st}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
