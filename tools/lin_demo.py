#!/usr/bin/env python3
"""Move two TMC211 nodes over LIN and plot their positions.

A small LIN master on the pty of ``ecatsim lin`` (started here on a temporary pty unless
``--pty`` names a running one): it wakes the bus, activates both nodes with GetFullStatus,
sets their motor parameters, gives them GetActualPos identifiers, sends both to a target
with one SetPosition frame, turns one of them around half-way, and polls their positions
every 20 ms. With matplotlib installed it draws the positions over time (``-o``); without,
it prints them.

    tools/lin_demo.py -o lin-demo.png               # starts its own ecatsim lin
    tools/lin_demo.py --pty /tmp/lin0 -o demo.png   # against a running one (config/lin-bus.yaml)
"""

from __future__ import annotations

import argparse
import os
import select
import subprocess
import sys
import tempfile
import time
import tty
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ecatsim.lin import codec  # noqa: E402
from ecatsim.lin.frame import MASTER_REQUEST, SLAVE_RESPONSE, classic_checksum, frame, header  # noqa: E402
from ecatsim.lin.tables import Cmd, RomPointer  # noqa: E402

NODES = {"left": 0x01, "right": 0x02}  # physical addresses of config/lin-bus.yaml
ACTPOS_ID = {"left": 0x21, "right": 0x22}  # Table 15's example "100xxx", xxx = AD[2:0]
PARAMS = {
    # Irun, Ihold, Vmax, Vmin, SecPos (0x400: none), Shaft, Acc, AccShape, StepMode
    "left": codec.MotorParams(10, 3, 5, 2, 0x400, 0, 2, 0, 3),  # 228 FS/s, Acc 1004 FS/s²
    "right": codec.MotorParams(10, 3, 9, 4, 0x400, 0, 1, 0, 3),  # 334 FS/s, Acc 218 FS/s²
}


class Master:
    """A LIN master writing and reading the pty like a UART."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.fd)

    def _drain(self, want: int, timeout: float) -> bytes:
        out = b""
        end = time.monotonic() + timeout
        while len(out) < want:
            left = end - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                break
            out += os.read(self.fd, 64)
        return out

    def send(self, ident: int, data: bytes) -> None:
        os.write(self.fd, frame(ident, data))
        time.sleep(0.012)  # T_frame_max of an 8-byte frame at 19.2 kbit/s, and a bit

    def read(self, ident: int, n: int) -> bytes | None:
        os.write(self.fd, header(ident))
        out = self._drain(n + 1, 0.012)
        if len(out) != n + 1 or classic_checksum(out[:-1]) != out[-1]:
            return None
        return out[:-1]

    def app(self, cmd: int, ad: int, params: bytes) -> None:
        data = bytes((codec.APP_CMD, 0x80 | cmd, 0x80 | ad)) + params
        self.send(MASTER_REQUEST, data + b"\xff" * (8 - len(data)))

    def full_status(self, ad: int) -> bytes | None:
        self.app(Cmd.GET_FULL_STATUS, ad, b"")
        first = self.read(SLAVE_RESPONSE, 8)
        self.read(SLAVE_RESPONSE, 8)
        return first


def run(m: Master, seconds: float) -> dict[str, list[tuple[float, int]]]:
    m.read(0x3E, 8)  # any header wakes sleeping nodes (they do not answer it)
    time.sleep(0.15)  # the wait a LIN master keeps after a wake-up
    for name, ad in NODES.items():
        if m.full_status(ad) is None:
            raise SystemExit(f"node {name} (0x{ad:02X}) does not answer GetFullStatus")
        m.app(Cmd.SET_MOTOR_PARAM, ad, codec.encode_motor_params(PARAMS[name]))
        m.app(Cmd.DYNAMIC_ID, ad, codec.pack_dynamic_ids([(RomPointer.GET_ACTUAL_POS,
                                                             ACTPOS_ID[name])]))  # fmt: skip
    # one reserved-ID frame for both motors (§6.11.12): left to 24000, right to -16000
    left, right = NODES["left"], NODES["right"]
    both = bytes((*codec.u16(24000), 0x80 | right, *codec.u16(-16000)))
    m.app(Cmd.SET_POSITION, left, both)
    t0 = time.monotonic()
    trace: dict[str, list[tuple[float, int]]] = {name: [] for name in NODES}
    turned = False
    while (now := time.monotonic() - t0) < seconds:
        if not turned and now > 0.4 * seconds:  # right turns around: linear zero crossing
            m.app(Cmd.SET_POSITION, right, bytes((*codec.u16(0), 0x80 | 0x7F, 0, 0)))
            turned = True
        for name in NODES:
            r = m.read(ACTPOS_ID[name], 4)
            if r is not None:
                trace[name].append((time.monotonic() - t0, codec.s16(r[1], r[2])))
        time.sleep(0.02)
    return trace


def plot(trace: dict[str, list[tuple[float, int]]], out: Path) -> bool:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(8, 4))
    for name, points in trace.items():
        ax.plot([t for t, _ in points], [p / 16 for _, p in points], label=f"{name} ActPos")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position [full steps]")
    ax.set_title("Two TMC211 nodes on ecatsim's LIN bus (GetActualPos every 20 ms)")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    return True


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pty", type=Path, help="a running ecatsim lin (config/lin-bus.yaml)")
    ap.add_argument("-o", "--output", type=Path, default=Path("lin-demo.png"))
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    proc = None
    link = args.pty
    if link is None:
        tmp = Path(tempfile.mkdtemp(prefix="lin-demo-"))
        link = tmp / "lin0"
        cfg = tmp / "bus.yaml"
        cfg.write_text(
            "nodes:\n  - {name: left, otp: [0, 0, 1, 0, 0, 0, 0, 0]}\n"
            "  - {name: right, otp: [0, 0, 2, 0, 0, 0, 0, 0]}\n"
        )
        cmd = [sys.executable, "-m", "ecatsim", "lin", "--pty", str(link), "--config", str(cfg),
               "--ctl", str(tmp / "ctl.sock")]  # fmt: skip
        proc = subprocess.Popen(cmd, stderr=subprocess.DEVNULL, cwd=ROOT)
        for _ in range(100):
            if link.exists():
                break
            time.sleep(0.05)
    try:
        trace = run(Master(link), args.seconds)
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=10)
    for name, points in trace.items():
        print(f"{name}: {len(points)} samples, last position {points[-1][1] if points else '?'}")
    if plot(trace, args.output):
        print(f"plot: {args.output}")
    else:
        print("matplotlib not installed (pip install -e '.[plot]'): positions only")
        for name, points in trace.items():
            print(name, " ".join(f"{t:.2f}:{p}" for t, p in points[::10]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
