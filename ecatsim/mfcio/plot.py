"""``ecatsim plot FILE.mfcio.csv``: the stepper of a TMC8460 MFCIO slave over time.

Three panels from the MFCIO trace (:mod:`ecatsim.mfcio.trace`): the step counter SD_SC
with the step rate it was asked for, the motor position in microsteps, the encoder ENC_X;
SAFEOP and OP shaded, the longer AL states named. Needs the ``plot`` extra (matplotlib).

Ref: TMC8460 datasheet §6.5 (step/direction: SD_SC, SD_SR), §6.3 (encoder: ENC_X).
"""

from __future__ import annotations

from pathlib import Path

from ecatsim.device.trace import read_trace, save_figure
from ecatsim.errors import UserError
from ecatsim.mfcio.trace import COLUMNS

#: AL state names by their AL status code. Ref: TMC8460 §5.20 Table 32.
AL_NAMES = {1: "INIT", 2: "PREOP", 3: "BOOT", 4: "SAFEOP", 8: "OP"}


def al_spans(t: list[float], states: list[int]) -> list[tuple[float, float, str]]:
    """(start, end, name) of each stretch in one AL state."""
    spans: list[tuple[float, float, str]] = []
    start, cur = t[0], states[0]
    for ti, st in zip([*t[1:], t[-1]], [*states[1:], -1], strict=True):
        if st != cur:
            spans.append((start, ti, AL_NAMES.get(cur, f"0x{cur:X}")))
            start, cur = ti, st
    return spans


def plot_mfcio(csv_path: Path, out: Path, slave: int | None = None) -> None:
    """Steps, motor position and encoder of one MFCIO slave (None: the first in the file)
    against time, the AL states shaded and named."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise UserError("ecatsim plot needs matplotlib: pip install 'ecatsim[plot]'") from exc
    rows = read_trace(csv_path, slave, COLUMNS)
    slave = int(rows[0]["slave"])
    t = [float(r["time_s"]) for r in rows]
    steps = [int(r["sd_sc"]) for r in rows]
    micro = [int(r["microsteps"]) if r["microsteps"] else None for r in rows]
    enc = [int(r["enc_x"]) for r in rows]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7))
    panels = (
        (steps, "steps (SD_SC)", "tab:blue"),
        (micro, "motor position [microsteps]", "tab:orange"),
        (enc, "encoder (ENC_X) [counts]", "tab:green"),
    )
    spans = al_spans(t, [int(r["al_state"]) for r in rows])
    for ax, (values, label, color) in zip(axes, panels, strict=True):
        ax.plot(t, values, color=color, lw=1.6, drawstyle="steps-post")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        for a, b, name in spans:
            if name in ("SAFEOP", "OP"):
                ax.axvspan(a, b, color="tab:green" if name == "OP" else "tab:blue", alpha=0.07)
    wide = 0.06 * (t[-1] - t[0])
    for a, b, name in spans:
        if b - a < wide:  # too short to name without overlapping its neighbours
            continue
        axes[0].annotate(
            name, ((a + b) / 2, 1.0), xycoords=("data", "axes fraction"), ha="center",
            va="bottom", fontsize=9, fontweight="bold",
        )  # fmt: skip
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{csv_path.name}: MFCIO slave {slave}, step/dir and encoder", y=0.995)
    fig.tight_layout()
    save_figure(fig, out)
    plt.close(fig)
