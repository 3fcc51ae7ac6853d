"""Long frame-fuzz run: mutated frames from a recorded pysoem bring-up through the frame
path, in process. Reports progress, the error counters, memory, and at the end whether a
master still brings the segment to OP. Same mutations as the 100k test in CI, more of them.

    .venv/bin/python tools/fuzz_frames.py --frames 10000000 --seed 1 --slaves 4
"""

from __future__ import annotations

import argparse
import logging
import random
import sys
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import structlog  # noqa: E402

from tests.perf.hotpath import configure_to_op, op_segment  # noqa: E402
from tests.support.fuzz import mutate, seed_frames  # noqa: E402
from tests.support.tinymaster import TinyMaster  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--slaves", type=int, default=2)
    ap.add_argument("--report", type=int, default=500_000, help="progress every N frames")
    args = ap.parse_args()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.ERROR))
    m, _frame, _n = op_segment(args.slaves)
    seg = m.seg
    rng = random.Random(args.seed)
    seeds = seed_frames()
    buf = bytearray(2048)
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.monotonic()
    errors = 0
    for i in range(1, args.frames + 1):
        f = mutate(rng, seeds[i % len(seeds)])
        buf[: len(f)] = f
        try:
            if len(f) >= 16:
                seg.process(buf, 14, len(f))
            seg.service()
        except Exception as exc:  # the finding this tool exists for
            errors += 1
            print(f"frame {i}: {exc!r} on {f.hex()}", file=sys.stderr)
        if i % args.report == 0:
            mem = tracemalloc.get_traced_memory()[0] - base
            rate = i / (time.monotonic() - t0)
            print(
                f"{i:>10} frames  {rate:8.0f}/s  bad {seg.bad_frames}  exceptions {errors}  "
                f"memory +{mem / 1e6:.2f} MB  pu_errors {seg.escs[0].mem[0x030C]}"
            )
    t = TinyMaster(seg)
    configure_to_op(t, args.slaves)
    r = t.brd(0x0130, 2)
    ok = r.data == b"\x08\x00" and r.wkc == args.slaves and errors == 0
    verdict = "OK" if ok else "FAIL"
    print(f"after {args.frames} frames: AL status {r.data.hex()} wkc {r.wkc}: {verdict}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
