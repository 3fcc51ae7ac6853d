"""Record the frames a real pysoem master sends while it brings ecatsim drives to OP (with
DC) and exchanges process data, into a pcap file that the fuzz tests mutate (and replay
unmutated afterwards: the recording ends with the slaves in OP).

    sudo .venv/bin/python tools/record_bringup.py -o tests/data/pysoem_bringup.pcap

Runs the daemon and the master in a private namespace pair (removed afterwards) and
keeps the master's EtherCAT frames (the requests) from the bench's capture on its end.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.bench.capture import Capture  # noqa: E402
from ecatsim.bench.master import request_op  # noqa: E402
from ecatsim.bench.netns import Daemon, NetnsPair, in_netns  # noqa: E402
from ecatsim.link.pcap import PcapWriter  # noqa: E402

#: whole frames (the pcap replays them)
SNAP = 2048


def bring_up(iface: str, slaves: int, cycles: int) -> None:
    import pysoem

    m = pysoem.Master()
    m.open(iface)
    try:
        if m.config_init() != slaves:
            raise SystemExit("record: the master did not find the slaves")
        for s in m.slaves:
            s.sdo_read(0x1018, 1)
            s.sdo_write(0x6060, 0, b"\x08")
        m.config_dc()
        m.config_map()
        m.state_check(pysoem.SAFEOP_STATE, 2_000_000)
        if not request_op(m, cycles, 50_000, 2000):
            raise SystemExit("record: the slaves did not reach OP")
        for _ in range(cycles):
            m.send_processdata()
            m.receive_processdata(50_000)
    finally:
        m.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", type=Path, required=True)
    ap.add_argument("--slaves", type=int, default=2)
    ap.add_argument("--cycles", type=int, default=50)
    args = ap.parse_args()
    with NetnsPair() as pair, tempfile.TemporaryDirectory() as tmp:
        daemon = Daemon(pair, ("--slaves", str(args.slaves)), Path(tmp) / "daemon.log")
        daemon.start()
        try:
            cap = Capture.master_end(pair.master_ns, pair.master_if, SNAP)
            with cap, in_netns(pair.master_ns):
                bring_up(pair.master_if, args.slaves, args.cycles)
        finally:
            daemon.stop()
    # the master's requests: the EtherCAT frames it sent
    frames = [data for _t, reply, data in cap.raw if data[12:14] == b"\x88\xa4" and not reply]
    with PcapWriter(args.output) as w:
        for f in frames:
            w.write(f)
    print(f"{args.output}: {len(frames)} frames")


if __name__ == "__main__":
    main()
