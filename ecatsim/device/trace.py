"""Per-cycle drive trace (CSV) and its plot.

One row per process-data exchange of each drive: time, controlword, statusword, mode,
PDS state, target and actual position, velocity and torque.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO, Any

from ecatsim.errors import UserError
from ecatsim.files import open_trace

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
        self._f: IO[str] = open_trace(path)
        self._w = csv.writer(self._f)
        self._w.writerow(COLUMNS)
        self.t0: int | None = None

    def row(self, now_ns: int, slave: int, values: tuple[int | str, ...]) -> None:
        if self.t0 is None:
            self.t0 = now_ns
        self._w.writerow((f"{(now_ns - self.t0) / 1e9:.6f}", slave, *values))

    def close(self) -> None:
        self._f.close()


def trace_columns(csv_path: Path) -> tuple[str, ...]:
    """The header of a CSV file (empty where it cannot be read: :func:`read_trace` says
    why)."""
    try:
        with open(csv_path, newline="", encoding="utf-8") as f:
            return tuple(next(csv.reader(f), ()))
    except (OSError, UnicodeDecodeError, csv.Error):
        return ()


def read_trace(
    csv_path: Path, slave: int | None, columns: tuple[str, ...] = COLUMNS
) -> list[dict[str, str]]:
    """The rows of one slave (None: the first in the file) of a ``--trace`` CSV with
    ``columns``; anything else is one line saying why."""
    hint = "write one with 'ecatsim run --trace FILE.csv'"
    try:
        with open(csv_path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            header = tuple(reader.fieldnames or ())
            if header[: len(columns)] != columns:
                missing = [c for c in columns if c not in header]
                what = (
                    f"columns {', '.join(missing[:3])} missing"
                    if missing
                    else "columns out of order"
                )
                raise UserError(f"{csv_path}: not an ecatsim trace ({what}); {hint}")
            rows = []
            for r in reader:
                if slave is None:
                    slave = int(r["slave"])
                if int(r["slave"]) == slave:
                    rows.append(r)
    except OSError as exc:
        raise UserError(f"{csv_path}: cannot read ({exc.strerror})") from exc
    except UnicodeDecodeError:
        raise UserError(
            f"{csv_path}: not an ecatsim trace (binary, not CSV text); {hint}"
        ) from None
    except (ValueError, csv.Error) as exc:
        raise UserError(f"{csv_path}: not an ecatsim trace (bad row: {exc}); {hint}") from exc
    if not rows:
        which = "" if slave is None else f" for slave {slave}"
        raise UserError(f"{csv_path}: no rows{which} (use --slave N)")
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


#: what the short names stand for, for the plot's key
STATE_LONG = {short: long.lower().replace("_", " ") for long, short in STATE_ABBREV.items()}


def state_key(labels: list[str]) -> str:
    """The key to the state names the marks use (CiA 402 PDS states), in the order of
    first use: ``SOD switch on disabled, RTSO ready to switch on, ...``."""
    seen: list[str] = []
    for label in labels:
        for name in label.split("→"):
            if name in STATE_LONG and name not in seen:
                seen.append(name)
    if not seen:
        return ""
    return "CiA 402 states: " + ", ".join(f"{n} {STATE_LONG[n]}" for n in seen)


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


def save_figure(fig: Any, out: Path, dpi: int = 110, option: str = "-o") -> None:
    """Render ``fig`` in the format its suffix names, then write it atomically: a bad
    path or format is one line, and no partial file is left."""
    import io

    from ecatsim.files import write_output

    buf = io.BytesIO()
    fmt = out.suffix[1:].lower() or "png"
    try:
        fig.savefig(buf, dpi=dpi, format=fmt)
    except ValueError as exc:
        raise UserError(f"{option} {out}: {exc} (use .png, .svg or .pdf)") from None
    write_output(out, buf.getvalue(), option)


def plot(csv_path: Path, out: Path, slave: int | None = None) -> None:
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
    slave = int(rows[0]["slave"])
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
    key = state_key([text for _t, text in marks])
    if key:
        fig.text(0.01, 0.005, key, fontsize=7, color="dimgrey", ha="left", va="bottom")
    fig.tight_layout(rect=(0, 0.02 if key else 0, 1, 1))
    save_figure(fig, out)
    plt.close(fig)
