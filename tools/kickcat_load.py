"""KickCAT against the daemon with both CPUs busy: how many of N runs reach OP and run 500
cycles. Each run: a fresh veth pair in two namespaces, the daemon with its default flags,
one spinning process per CPU at nice 0, then tools/kickcat_master.py. Root.
    .venv/bin/python tools/kickcat_load.py --runs 20
Writes bench/results/kickcat-load-<time>.json and prints k/N.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.bench.netns import Daemon, NetnsPair  # noqa: E402
from tests.support.kickcat import busy_cpus, kickcat_trial  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--idle", action="store_true", help="no busy processes")
    ap.add_argument("--daemon-arg", action="append", default=[], help="extra daemon flag")
    ap.add_argument(
        "--master-rt", type=int, help="run KickCAT SCHED_FIFO at this priority (default: nice 0)"
    )
    args = ap.parse_args()
    results = []
    for i in range(args.runs):
        with NetnsPair() as pair:
            d = Daemon(pair, args.daemon_arg, Path(f"/tmp/kickcat-load-{os.getpid()}-{i}.log"))
            d.start()
            try:
                if args.idle:
                    r = kickcat_trial(pair, master_rt=args.master_rt)
                else:
                    with busy_cpus(os.cpu_count() or 2):
                        r = kickcat_trial(pair, master_rt=args.master_rt)
            finally:
                d.stop()
        results.append(r)
        print(f"run {i + 1}: {'OP + 500 cycles' if r['ok'] else r}", flush=True)
    ok = sum(r["ok"] for r in results)
    out = ROOT / "bench" / "results" / f"kickcat-load-{time.strftime('%Y%m%d-%H%M%S')}.json"
    load = "idle" if args.idle else f"{os.cpu_count()} busy processes at nice 0"
    out.write_text(
        json.dumps(
            {
                "runs": args.runs,
                "ok": ok,
                "load": load,
                "daemon_args": args.daemon_arg,
                "master": f"SCHED_FIFO {args.master_rt}" if args.master_rt else "nice 0",
                "results": results,
            },
            indent=1,
        )
    )
    print(f"{ok}/{args.runs} runs reached OP and ran 500 cycles ({load}); {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
