"""In-process cost of the frames that touch every slave at once, as a bring-up sends them:
the time to the reply (the walk) and the work after it (the firmware's reactions), for N
TMC8670 drives in OP.

.venv/bin/python tools/broadcast_bench.py --slaves 128 --slaves 512

Frames: a BWR of 256 zero bytes to 0x0600 (clearing configured FMMUs, then clearing them
again), a BWR of 48 zero bytes to 0x0800 (the SMs), a BWR of INIT to 0x0120 (then the
firmware's INIT transitions after the reply), a BRD of 0x0130. Each figure is the best of
``--repeat`` tries, each on a segment brought back to OP. ``--save`` records them in
bench/results/broadcast-<time>.json (docs/performance.md).
"""

from __future__ import annotations

import argparse
import logging
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import structlog

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.bench import results  # noqa: E402
from ecatsim.compiled import core_line  # noqa: E402
from ecatsim.wire import datagram as dg  # noqa: E402
from ecatsim.wire.frame import ecat_offset, mark_processed  # noqa: E402
from tests.perf.hotpath import configure_to_op  # noqa: E402
from tests.support.tinymaster import TinyMaster, segment_of  # noqa: E402


def timed(m: TinyMaster, datagram: bytes) -> tuple[float, float]:
    """One frame: seconds to the reply (walk), seconds of the work after it."""
    raw = bytearray(dg.ethernet_frame([datagram]))
    n = len(raw)
    off = ecat_offset(raw, n, True)
    seg = m.seg
    t0 = time.perf_counter()
    seg.process(raw, off, n)
    mark_processed(raw)
    t1 = time.perf_counter()
    seg.service()
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1


def run(n: int, repeat: int) -> dict[str, tuple[float, float]]:
    seg, _ = segment_of(n, device="tmc8670")
    m = TinyMaster(seg)
    best: dict[str, tuple[float, float]] = {}

    def keep(name: str, r: tuple[float, float]) -> None:
        old = best.get(name)
        best[name] = r if old is None else (min(old[0], r[0]), min(old[1], r[1]))

    for _ in range(repeat):
        configure_to_op(m, n)
        keep("BRD 0x0130", timed(m, dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))))
        keep("BWR INIT 0x0120", timed(m, dg.build(dg.Cmd.BWR, 0, 0x0120, b"\x01\x00")))
        keep("BWR 256x0 0x0600 (configured)", timed(m, dg.build(dg.Cmd.BWR, 0, 0x0600, bytes(256))))
        keep("BWR 256x0 0x0600 (already 0)", timed(m, dg.build(dg.Cmd.BWR, 0, 0x0600, bytes(256))))
        keep("BWR 48x0 0x0800", timed(m, dg.build(dg.Cmd.BWR, 0, 0x0800, bytes(48))))
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--slaves", type=int, action="append")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--save", action="store_true", help="record the run in bench/results")
    args = ap.parse_args()
    # the firmware logs each AL transition: not part of the cost measured here
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING))
    print(core_line())
    out: dict[str, Any] = {"when": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
                           "machine": platform.node(), "core": core_line(),
                           "load_1min": os.getloadavg()[0], "repeat": args.repeat,
                           "runs": []}  # fmt: skip
    for n in args.slaves or [128, 512]:
        for name, (walk, after) in run(n, args.repeat).items():
            print(
                f"{n:4d} slaves  {name:32s} reply {walk * 1e6:9.1f} us  after {after * 1e6:9.1f} us"
            )
            out["runs"].append({"slaves": n, "frame": name, "reply_us": round(walk * 1e6, 1),
                                "after_us": round(after * 1e6, 1)})  # fmt: skip
    if args.save:
        results.write(results.DEFAULT_DIR, "broadcast", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
