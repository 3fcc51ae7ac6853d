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


#: short names of the PDS states for plot labels. Ref: CiA 402-2 §8.1 (Figure 10).
STATE_ABBREV = {
    "NOT_READY_TO_SWITCH_ON": "NRTSO",
    "SWITCH_ON_DISABLED": "SOD",
    "READY_TO_SWITCH_ON": "RTSO",
    "SWITCHED_ON": "SO",
    "OPERATION_ENABLED": "OE",
    "QUICK_STOP_ACTIVE": "QSA",
    "FAULT_REACTION_ACTIVE": "FRA",
    "FAULT": "F",
}

#: names of the modes of operation (6061h). Ref: CiA 402-2 Table 35.
MODE_NAMES = {1: "pp", 3: "pv", 4: "tq", 6: "hm", 7: "ip", 8: "csp", 9: "csv", 10: "cst"}


def state_marks(t: list[float], rows: list[dict[str, str]]) -> list[tuple[float, str]]:
    """State changes as (time, label); changes closer than 3 % of the time span share one
    label (``SOD→RTSO→SO→OE``) so the labels of a quick enable sequence do not overlap."""
    gap = 0.03 * (t[-1] - t[0]) if len(t) > 1 else 0.0
    marks: list[tuple[float, list[str]]] = []
    prev = rows[0]["state"]
    for ti, r in zip(t, rows, strict=True):
        state = r["state"]
        if state == prev:
            continue
        name = STATE_ABBREV.get(state, state)
        if marks and ti - marks[-1][0] <= gap:
            marks[-1][1].append(name)
        else:
            marks.append((ti, [STATE_ABBREV.get(prev, prev), name]))
        prev = state
    return [(ti, "→".join(names)) for ti, names in marks]


def mode_spans(t: list[float], rows: list[dict[str, str]]) -> list[tuple[float, float, str]]:
    """(start, end, mode name) of each stretch in one mode of operation (mode 0 left out)."""
    spans: list[tuple[float, float, str]] = []
    start, mode = t[0], rows[0]["mode"]
    for ti, r in zip([*t[1:], t[-1]], [*rows[1:], {"mode": ""}], strict=True):
        if r["mode"] != mode:
            if mode not in ("", "0"):
                spans.append((start, ti, MODE_NAMES.get(int(mode), f"mode {mode}")))
            start, mode = ti, r["mode"]
    return spans


def plot(csv_path: Path, out: Path, slave: int = 0) -> None:
    """Position, velocity and torque against time: the set point dashed over the actual
    value, the modes of operation shaded and named, state changes marked. Needs the
    ``plot`` extra (matplotlib)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise UserError("ecatsim plot needs matplotlib: pip install 'ecatsim[plot]'") from exc
    rows = read_trace(csv_path, slave)
    t = [float(r["time_s"]) for r in rows]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    spans = mode_spans(t, rows)
    marks = state_marks(t, rows)
    for ax, (target, actual, label) in zip(
        axes,
        (
            ("target_position", "position", "position [counts]"),
            ("target_velocity", "velocity", "velocity [rpm]"),
            ("target_torque", "torque", "torque current [mA]"),
        ),
        strict=True,
    ):
        ax.plot(t, [int(r[actual]) for r in rows], color="tab:orange", label="actual", lw=1.6)
        ax.plot(t, [int(r[target]) for r in rows], "--", color="black", label="set point", lw=0.9)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        for i, (a, b, _name) in enumerate(spans):
            ax.axvspan(a, b, color="tab:blue" if i % 2 == 0 else "tab:green", alpha=0.07, lw=0)
        for ti, _text in marks:
            ax.axvline(ti, color="grey", alpha=0.5, linewidth=0.8)
    top = axes[0]
    for a, b, name in spans:
        top.annotate(
            name, ((a + b) / 2, 1.0), xycoords=("data", "axes fraction"), ha="center",
            va="bottom", fontsize=9, fontweight="bold",
        )  # fmt: skip
    for ti, text in marks:
        top.annotate(
            text, (ti, 0.03), xycoords=("data", "axes fraction"), rotation=90, fontsize=7,
            va="bottom", ha="right",
        )  # fmt: skip
    top.legend(loc="upper left")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{csv_path.name}: slave {slave}", y=0.995)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
