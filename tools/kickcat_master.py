"""Bring the segment to OP with KickCAT (default settings) and run cyclic process data.

One trial: INIT scan, mapping, SAFE_OP, OP, then ``--cycles`` process-data exchanges at 1 ms.
Prints one JSON line ({"ok": ..., "stage": ..., "error": ...}) and exits 0 only if every step
and every cycle passed. KickCAT keeps its defaults (2 ms link timeout): the point is that a
stock master does not notice the emulator.
    .venv/bin/python tools/kickcat_master.py --iface ecat0 --cycles 500
"""

from __future__ import annotations

import argparse
import json
import sys
import time


def trial(iface: str, cycles: int) -> dict[str, object]:
    import kickcat

    stage = "open"
    try:
        bus = kickcat.Bus(kickcat.create_link(iface, ""))
        stage = "init"
        bus.init(0.1)
        slaves = len(bus.slaves())
        stage = "mapping"
        bus.create_mapping()
        stage = "safe_op"
        bus.request_state(kickcat.State.SAFE_OP)
        bus.wait_for_state(kickcat.State.SAFE_OP, 1.0)
        stage = "op"
        bus.process_data()
        bus.request_state(kickcat.State.OPERATIONAL)
        bus.wait_for_state(kickcat.State.OPERATIONAL, 1.0, lambda: bus.process_data())
        stage = "cycles"
        for _ in range(cycles):
            bus.process_data()
            time.sleep(0.001)
    except Exception as exc:
        return {"ok": False, "stage": stage, "error": f"{type(exc).__name__}: {exc}"}
    return {"ok": True, "stage": "done", "slaves": slaves, "cycles": cycles}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iface", required=True, help="the master's end of the link")
    ap.add_argument("--cycles", type=int, default=500, help="process-data cycles after OP")
    args = ap.parse_args()
    result = trial(args.iface, args.cycles)
    print(json.dumps(result), flush=True)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
