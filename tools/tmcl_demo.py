#!/usr/bin/env python3
"""Drive an emulated (or real) TMCM-1311 with pytrinamic and plot what the axis did.

Start the module first, then run this script:

    ecatsim tmcl --listen tcp://127.0.0.1:2323
    .venv/bin/python tools/tmcl_demo.py --connect 127.0.0.1:2323 -o tmcl-demo.png

``--connect`` takes HOST:PORT (pytrinamic's socket_serial_tmcl interface) or the path of a
serial port or pty (its serial_tmcl interface, e.g. ``ecatsim tmcl --listen pty:/tmp/tmcm``).
The script moves the axis out and back in position mode, then rotates and stops in velocity
mode, sampling actual position (axis parameter 1) and actual speed (3) every 20 ms. It
prints the samples as CSV; with matplotlib installed it also draws them into ``-o``.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path


def connect(where: str):  # type: ignore[no-untyped-def]
    """The pytrinamic interface to ``where``; None (and one line saying how to start the
    emulated module) where nothing answers there."""
    from pytrinamic.connections import SerialTmclInterface, SocketTmclInterface

    tcp = re.match(r"^\d+\.\d+\.\d+\.\d+:\d+$", where) is not None
    try:
        if tcp:
            return SocketTmclInterface(where)
        return SerialTmclInterface(where, timeout_s=2)
    except OSError as exc:  # serial.SerialException is an OSError too
        cause: BaseException | None = exc  # pytrinamic wraps the socket's error
        while cause is not None and not getattr(cause, "strerror", None):
            cause = cause.__cause__ or cause.__context__
        why = getattr(cause, "strerror", None) or str(exc)
        line = f"tcp://{where}" if tcp else f"pty:{where}"
        print(
            f"tmcl_demo: no TMCL module at {where} ({why}): start one first with "
            f"'.venv/bin/ecatsim tmcl --listen {line}'",
            file=sys.stderr,
        )
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--connect", default="127.0.0.1:2323", help="HOST:PORT or a serial port")
    ap.add_argument("-o", "--output", type=Path, default=Path("tmcl-demo.png"))
    ap.add_argument("--period", type=float, default=0.02, help="sampling period, s")
    args = ap.parse_args()

    from pytrinamic.modules import TMCM1311

    iface = connect(args.connect)
    if iface is None:
        return 1
    module = TMCM1311(iface)
    motor = module.motors[0]
    AP = motor.AP
    print(f"# {iface.get_version_string()} at {args.connect}", file=sys.stderr)
    motor.set_axis_parameter(AP.MaxVelocity, 102_400)
    motor.set_axis_parameter(AP.MaxAcceleration, 204_800)
    samples: list[tuple[float, int, int, int, str]] = []
    t0 = time.monotonic()

    def sample_for(seconds: float, phase: str) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            t = time.monotonic() - t0
            samples.append(
                (t, motor.actual_position, motor.actual_velocity, motor.target_position, phase)
            )
            time.sleep(args.period)

    module.move_to(0, 204_800)  # four turns at 256 microsteps, 200 full steps
    sample_for(2.6, "MVP ABS 204800")
    module.move_to(0, 0)
    sample_for(2.6, "MVP ABS 0")
    module.rotate(0, 60_000)
    sample_for(1.2, "ROR 60000")
    module.stop(0)
    sample_for(0.8, "MST")
    iface.close()

    print("t_s,position,velocity,target,phase")
    for t, pos, vel, target, phase in samples:
        print(f"{t:.3f},{pos},{vel},{target},{phase}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("# matplotlib not installed: no plot", file=sys.stderr)
        return 0
    ts = [s[0] for s in samples]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(9, 6.5))
    ax1.plot(ts, [s[3] for s in samples], "--", color="grey", label="target position (AP 0)")
    ax1.plot(ts, [s[1] for s in samples], label="actual position (AP 1)")
    ax1.set_ylabel("microsteps")
    ax2.plot(ts, [s[2] for s in samples], color="tab:orange", label="actual speed (AP 3)")
    ax2.set_ylabel("microsteps/s")
    ax2.set_xlabel("s")
    for ax in (ax1, ax2):  # below each plot: the phase names along the top stay readable
        ax.legend(loc="upper right", bbox_to_anchor=(1, -0.08), ncol=2, fontsize=8, frameon=False)
    lo, hi = ax1.get_ylim()
    ax1.set_ylim(lo, hi + 0.12 * (hi - lo))  # room above the curves for the phase names
    last = None
    for t, *_, phase in samples:
        if phase != last:
            for ax in (ax1, ax2):
                ax.axvline(t, color="lightgrey", lw=0.8)
            ax1.annotate(
                phase,
                (t, 1),
                xycoords=("data", "axes fraction"),
                fontsize=8,
                va="top",
                xytext=(3, -3),
                textcoords="offset points",
            )
            last = phase
    fig.suptitle("TMCM-1311 (ecatsim tmcl) driven by pytrinamic")
    fig.tight_layout()
    try:
        fig.savefig(args.output)
    except OSError as exc:
        print(f"tmcl_demo: -o {args.output}: cannot write ({exc.strerror})", file=sys.stderr)
        return 1
    print(f"# {args.output}: written", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
