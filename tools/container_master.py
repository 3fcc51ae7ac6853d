"""Minimal pysoem master for tools/container-test.sh: find exactly one slave on IFACE, map
its process data, bring it through SAFEOP to OP and check the working counter.

Prints ``container: slave NAME reached OP, wkc N`` and exits 0, or exits 1 with the reason.
Run it in the namespace that holds IFACE (needs CAP_NET_RAW)."""

from __future__ import annotations

import argparse
import sys

import pysoem

CYCLES = 20
TIMEOUT_US = 2_000_000


class MasterError(Exception):
    pass


def _states(master: pysoem.Master) -> str:
    master.read_state()
    return ", ".join(
        f"{s.name}: state 0x{s.state:02X} AL 0x{s.al_status:04X}" for s in master.slaves
    )


def _cycle(master: pysoem.Master) -> int:
    master.send_processdata()
    wkc: int = master.receive_processdata(10_000)
    return wkc


def bring_to_op(iface: str) -> tuple[str, int]:
    """Open ``iface``, bring its single slave to OP; return (slave name, last WKC)."""
    master = pysoem.Master()
    try:
        master.open(iface)
    except Exception as e:
        raise MasterError(f"cannot open {iface}: {e}") from e
    try:
        n = master.config_init()
        if n != 1:
            raise MasterError(f"config_init() found {n} slaves on {iface}, expected 1")
        master.config_map()
        if master.state_check(pysoem.SAFEOP_STATE, TIMEOUT_US) != pysoem.SAFEOP_STATE:
            raise MasterError(f"SAFEOP not reached: {_states(master)}")
        expected = int(master.expected_wkc)
        if expected <= 0:
            raise MasterError(f"expected WKC {expected}: no process data mapped")
        master.state = pysoem.OP_STATE
        _cycle(master)
        master.write_state()
        for _ in range(200):
            _cycle(master)
            if master.state_check(pysoem.OP_STATE, 5000) == pysoem.OP_STATE:
                break
        else:
            raise MasterError(f"OP not reached: {_states(master)}")
        wkcs = [_cycle(master) for _ in range(CYCLES)]
        if any(w != expected for w in wkcs):
            raise MasterError(f"WKC {wkcs} in OP, expected {expected} every cycle")
        if master.read_state() != pysoem.OP_STATE or master.slaves[0].state != pysoem.OP_STATE:
            raise MasterError(f"not in OP after {CYCLES} cycles: {_states(master)}")
        name = str(master.slaves[0].name)
        master.state = pysoem.INIT_STATE
        master.write_state()
        return name, wkcs[-1]
    finally:
        master.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("iface", help="master end of the veth pair")
    args = ap.parse_args(argv)
    try:
        name, wkc = bring_to_op(args.iface)
    except MasterError as e:
        print(f"container: {e}", file=sys.stderr)
        return 1
    print(f"container: slave {name} reached OP, wkc {wkc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
