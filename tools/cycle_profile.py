"""One DC cycle in process, for profilers: N enabled TMC8670 drives in csp, SYNC0 every 1 ms,
the cycle's frames mid-way between pulses (the process image in LRWs of at most 1486 bytes,
cut as SOEM cuts it, one frame up to 50 drives; the FRMW of the DC system time in the
first), served by the daemon loop (`Daemon.handle_one` and its timers) on a loopback link
with a manual clock.

    .venv/bin/python tools/cycle_profile.py --drives 1 --cycles 2000          # us per cycle
    .venv/bin/python tools/cycle_profile.py --drives 16 --profile | head -40  # cProfile
    tools/icount.sh 1 --idle       # instructions per cycle (callgrind, two run lengths)
    tools/icount.sh 64 --hold --responder  # drives holding still (decision P81)
    tools/icount.sh 1 --responder  # the frame through the compiled responder
    tools/icount.sh 1 --cold       # code and data lines a frame misses in a cold L2
    tools/icount.sh 64 --footprint --hold   # the lines a whole cycle reads from memory

Ref: docs/performance.md.
"""

from __future__ import annotations

import argparse
import cProfile
import ctypes
import pstats
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.perf.hotpath import CspCycle  # noqa: E402


def before(c: CspCycle, method: str, first: Callable[[], object]) -> None:
    """Make ``c.<method>`` call ``first()`` before it does its own work."""
    inner = getattr(c, method)

    def wrapped(*args: Any) -> Any:
        first()
        return inner(*args)

    setattr(c, method, wrapped)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=1)
    ap.add_argument("--cycles", type=int, default=2000)
    ap.add_argument("--device", default="tmc8670", help="tmc8670 | echo")
    ap.add_argument("--idle", action="store_true", help="drives in OP but not enabled")
    ap.add_argument(
        "--hold",
        action="store_true",
        help="drives enabled in csp holding their position (the target stays 0), as SOEM's "
        "red_test leaves them",
    )
    ap.add_argument("--profile", action="store_true", help="cProfile, sorted by own time")
    ap.add_argument(
        "--responder",
        action="store_true",
        help="the frame through the compiled responder over a socket pair (decision P9)",
    )
    ap.add_argument(
        "--evict",
        type=int,
        default=0,
        metavar="MB",
        help="before each frame, read MB megabytes a byte per cache line, so the frame finds "
        "the caches cold, as after the master's own work on a shared CPU",
    )
    ap.add_argument(
        "--cold-cycle",
        type=int,
        default=0,
        metavar="MB",
        help="before each whole cycle (the SYNC0 pulse and the frame), write MB megabytes "
        "(memset, C), so the cycle finds every cache cold, as a daemon that slept while "
        "the master and the host ran (tools/icount.sh --footprint)",
    )
    args = ap.parse_args()
    c = CspCycle(
        args.drives,
        args.device,
        enable=not args.idle,
        responder=args.responder,
        amplitude=0 if args.hold else 20_000,
    )
    if args.cold_cycle:  # written in C: the memset's own lines are known (icount.sh)
        junk = ctypes.create_string_buffer(args.cold_cycle << 20)
        before(c, "step", lambda: ctypes.memset(junk, 1, len(junk)))
    if args.evict:
        evict = memoryview(bytearray(b"\1" * (args.evict << 20)))[::64]
        before(c, "deliver", lambda: sum(evict))
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
