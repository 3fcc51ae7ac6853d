"""In-process frame-path micro-benchmark: cost per cyclic frame for N slaves, and per DC
cycle with N drives in csp (the frame through the daemon's Python loop, and through the
compiled responder over a socket pair).

.venv/bin/python tools/microbench.py            # print
.venv/bin/python tools/microbench.py --save     # store tests/perf/baseline.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.perf.hotpath import calibrate, csp_cycle_cost, frame_cost  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--save", action="store_true")
    args = ap.parse_args()
    unit = calibrate()
    out = {}
    for n in (1, 4, 16, 64):
        c = frame_cost(n, iterations=2000 if n < 64 else 500)
        out[f"frame_{n}"] = round(c / unit, 1)
        print(f"{n:3d} slaves: {c * 1e6:8.1f} us/frame  ({c / unit:6.0f} calibration units)")
    for n in (1, 16):
        c = csp_cycle_cost(n)
        out[f"dc_csp_{n}"] = round(c / unit, 1)
        print(f"{n:3d} drives, DC csp: {c * 1e6:8.1f} us/cycle ({c / unit:6.0f} calibration units)")
    for n in (1, 16):
        c = csp_cycle_cost(n, responder=True)
        out[f"dc_csp_responder_{n}"] = round(c / unit, 1)
        print(f"{n:3d} drives, DC csp, compiled responder: {c * 1e6:8.1f} us/cycle "
              f"({c / unit:6.0f} calibration units)")  # fmt: skip
    if args.save:
        (ROOT / "tests/perf/baseline.json").write_text(json.dumps(out, indent=2) + "\n")
        print("saved tests/perf/baseline.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
