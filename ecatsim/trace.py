"""Per-cycle drive trace (CSV) and its plot.

One row per process-data exchange of each drive: time, controlword, statusword, mode,
PDS state, target and actual position, velocity and torque.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO

from ecatsim.errors import UserError

COLUMNS = (
    "time_s",
    "slave",
    "controlword",
    "statusword",
    "mode",
    "state",
    "target_position",
    "position",
    "target_velocity",
    "velocity",
    "target_torque",
    "torque",
)


class TraceWriter:
    """Appends rows to a CSV file; flushed on close."""

    def __init__(self, path: Path) -> None:
        try:
            self._f: IO[str] = open(path, "w", newline="")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise UserError(f"--trace {path}: cannot write ({exc.strerror})") from exc
        self._w = csv.writer(self._f)
        self._w.writerow(COLUMNS)
        self.t0: int | None = None

    def row(self, now_ns: int, slave: int, values: tuple[int | str, ...]) -> None:
        if self.t0 is None:
            self.t0 = now_ns
        self._w.writerow((f"{(now_ns - self.t0) / 1e9:.6f}", slave, *values))

    def close(self) -> None:
        self._f.close()


def read_trace(csv_path: Path, slave: int) -> list[dict[str, str]]:
    """The rows of one slave of a ``--trace`` CSV; anything else is one line saying why."""
    hint = "write one with 'ecatsim run --trace FILE.csv'"
    try:
        with open(csv_path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = tuple(reader.fieldnames or ())
            if header[: len(COLUMNS)] != COLUMNS:
                missing = [c for c in COLUMNS if c not in header]
                what = (
                    f"columns {', '.join(missing[:3])} missing"
                    if missing
                    else "columns out of order"
                )
                raise UserError(f"{csv_path}: not an ecatsim trace ({what}); {hint}")
            rows = [r for r in reader if int(r["slave"]) == slave]
    except OSError as exc:
        raise UserError(f"{csv_path}: cannot read ({exc.strerror})") from exc
    except UnicodeDecodeError:
        raise UserError(
            f"{csv_path}: not an ecatsim trace (binary, not CSV text); {hint}"
        ) from None
    except (ValueError, csv.Error) as exc:
        raise UserError(f"{csv_path}: not an ecatsim trace (bad row: {exc}); {hint}") from exc
    if not rows:
        raise UserError(f"{csv_path}: no rows for slave {slave} (use --slave N)")
    return rows


def plot(csv_path: Path, out: Path, slave: int = 0) -> None:
    """Position, velocity and torque against time, set point over actual, state changes
    marked. Needs the ``plot`` extra (matplotlib)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise UserError("ecatsim plot needs matplotlib: pip install 'ecatsim[plot]'") from exc
    rows = read_trace(csv_path, slave)
    t = [float(r["time_s"]) for r in rows]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    for ax, (target, actual, label) in zip(
        axes,
        (
            ("target_position", "position", "position [counts]"),
            ("target_velocity", "velocity", "velocity [rpm]"),
            ("target_torque", "torque", "torque current [mA]"),
        ),
        strict=True,
    ):
        ax.plot(t, [int(r[target]) for r in rows], "--", label="set point", linewidth=1)
        ax.plot(t, [int(r[actual]) for r in rows], label="actual", linewidth=1.2)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        prev = None
        for ti, r in zip(t, rows, strict=True):
            if r["state"] != prev and prev is not None:
                ax.axvline(ti, color="grey", alpha=0.4, linewidth=0.8)
                if ax is axes[0]:
                    ax.annotate(r["state"], (ti, 0), rotation=90, fontsize=6, va="bottom")
            prev = r["state"]
    axes[0].legend(loc="upper left")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{csv_path.name}: slave {slave}")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
