"""The MFCIO trace: one CSV row per run of each MFCIO block (after every frame), beside the
drives' ``--trace`` file as ``FILE.mfcio.csv``: step counter and rate, motor position,
encoder, PWM duty cycles and the six bridge outputs, GPIO, IRQ flags, watchdog, nES.

Pin levels are 0, 1 or Z (not driven: not OP, TMC8460 §6.1).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO

from ecatsim.files import open_trace
from ecatsim.mfcio.block import MfcioBlock

COLUMNS = (
    "time_s",
    "slave",
    "al_state",
    "sd_sc",
    "sd_sr",
    "microsteps",
    "enc_x",
    "enc_latch",
    "pwm_duty0",
    "pwm_duty1",
    "pwm_duty2",
    "pwm_hs0",
    "pwm_ls0",
    "pwm_hs1",
    "pwm_ls1",
    "pwm_hs2",
    "pwm_ls2",
    "gpio_pins",
    "gpi",
    "irq_flags",
    "wd_active",
    "emergency",
)


def trace_path(path: Path) -> Path:
    """Where the MFCIO rows of ``--trace PATH`` go: PATH with ``.mfcio.csv``."""
    return path.with_name(path.stem + ".mfcio.csv")


def _z(v: int | None) -> str:
    return "Z" if v is None else str(v)


class MfcioTrace:
    """Writes the rows of every MFCIO block of a segment; flushed on close."""

    def __init__(self, path: Path) -> None:
        self._f: IO[str] = open_trace(path)
        self.path = path
        self._w = csv.writer(self._f)
        self._w.writerow(COLUMNS)
        self.t0: int | None = None

    def row(self, now_ns: int, slave: int, b: MfcioBlock) -> None:
        if self.t0 is None:
            self.t0 = now_ns
        pins = b.pins(now_ns)
        st = b.status(now_ns)
        self._w.writerow(
            (
                f"{(now_ns - self.t0) / 1e9:.6f}",
                slave,
                b.state,
                st["sd_sc"],
                b.sd.sr,
                st["microsteps"] if st["microsteps"] is not None else "",
                st["enc_x"],
                st["enc_latch"],
                *(f"{d:.6f}" for d in b.duties()),
                *(_z(pins[f"PWM_{s}{ch}"]) for ch in range(3) for s in ("HS", "LS")),
                "".join(_z(pins[f"GPO{i}"]) for i in range(7, -1, -1)),
                f"0x{b.gpio.in_val(b.gpio_pins()):02X}",
                f"0x{b.irq.flags:04X}",
                int(b.wd.active),
                int(b.emergency),
            )
        )

    def close(self) -> None:
        self._f.close()


def attach(blocks: list[tuple[int, MfcioBlock]], path: Path) -> MfcioTrace | None:
    """Give each block a tracer writing into ``trace_path(path)``; None without blocks."""
    if not blocks:
        return None
    writer = MfcioTrace(trace_path(path))
    for pos, b in blocks:
        b.tracer = lambda now, blk, pos=pos: writer.row(now, pos, blk)
    return writer
