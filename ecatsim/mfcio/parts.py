"""The simulated parts a segment wires to the MFCIO pins: a stepper motor on STP/DIR with
an ABN encoder on its shaft, SPI devices on the chip selects, switches on the GPIO pins
and the emergency switch input.

Segment YAML, under a ``device: tmc8460`` slave::

    mfcio:
      stepper: {full_steps: 200, microsteps: 16, microsteps_per_pulse: 1}
      encoder: {counts_per_rev: 4000, index: true}   # on the stepper's shaft
      spi: [register_file, loopback, none, none]      # CS0..CS3
      gpio: {0: 1, 3: 0}                              # pins driven from outside
      nes: 1                                          # MFC_nES level (1: driven high)

Ref: TMC8460 §6.6.1 (A, B, N), §6.7.1 (CS0..3), §6.8 Table 143 (STP, DIR), §6.10, §6.13.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ecatsim.errors import UserError
from ecatsim.mfcio.encoder import Encoder
from ecatsim.mfcio.spi import DEVICE_KINDS


@dataclass(frozen=True, slots=True)
class StepperSpec:
    full_steps: int = 200
    microsteps: int = 16
    microsteps_per_pulse: int = 1

    @property
    def microsteps_per_rev(self) -> int:
        return self.full_steps * self.microsteps


@dataclass(frozen=True, slots=True)
class EncoderSpec:
    #: quadrature counts (A/B edges) per revolution
    counts_per_rev: int = 4000
    #: an N pulse one count wide at count 0 of every revolution (A = B = 0 there)
    index: bool = True


@dataclass(frozen=True, slots=True)
class Wiring:
    """What the segment file connects to the MFCIO pins."""

    stepper: StepperSpec | None = field(default_factory=StepperSpec)
    encoder: EncoderSpec | None = field(default_factory=EncoderSpec)
    spi: tuple[str, ...] = ("none", "none", "none", "none")
    gpio: tuple[int | None, ...] = (None,) * 8
    nes: int = 1


def _pos_int(src: str, key: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
        raise UserError(f"{src}: {key}: expected a positive integer, got {v!r}")
    return v


def _level(src: str, key: str, v: Any) -> int:
    if v not in (0, 1) or isinstance(v, bool):
        raise UserError(f"{src}: {key}: expected 0 or 1, got {v!r}")
    return int(v)


def _mapping(src: str, key: str, v: Any, allowed: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise UserError(f"{src}: {key}: expected a mapping with keys {', '.join(allowed)}")
    for k in v:
        if k not in allowed:
            raise UserError(f"{src}: {key}.{k}: unknown key (allowed: {', '.join(allowed)})")
    return v


def parse_wiring(raw: Any, src: str, key: str) -> Wiring:
    """The ``mfcio:`` mapping of a slave; every problem is one line naming the key."""
    if raw is None:
        return Wiring()
    d = _mapping(src, key, raw, ("stepper", "encoder", "spi", "gpio", "nes"))
    stepper: StepperSpec | None = StepperSpec()
    if "stepper" in d:
        if d["stepper"] is None:
            stepper = None
        else:
            s = _mapping(
                src,
                f"{key}.stepper",
                d["stepper"],
                ("full_steps", "microsteps", "microsteps_per_pulse"),
            )
            stepper = StepperSpec(
                **{k: _pos_int(src, f"{key}.stepper.{k}", v) for k, v in s.items()}
            )
    encoder: EncoderSpec | None = EncoderSpec()
    if "encoder" in d:
        if d["encoder"] is None:
            encoder = None
        else:
            e = _mapping(src, f"{key}.encoder", d["encoder"], ("counts_per_rev", "index"))
            cpr = _pos_int(src, f"{key}.encoder.counts_per_rev", e.get("counts_per_rev", 4000))
            idx = e.get("index", True)
            if not isinstance(idx, bool):
                raise UserError(f"{src}: {key}.encoder.index: expected true or false")
            encoder = EncoderSpec(cpr, idx)
    spi = ("none",) * 4
    if "spi" in d:
        lst = d["spi"]
        if not isinstance(lst, list) or len(lst) > 4 or any(k not in DEVICE_KINDS for k in lst):
            raise UserError(
                f"{src}: {key}.spi: expected a list of up to 4 of {', '.join(DEVICE_KINDS)}"
                " (CS0 first)"
            )
        spi = (*lst, *(["none"] * (4 - len(lst))))
    gpio: list[int | None] = [None] * 8
    if "gpio" in d:
        g = d["gpio"]
        if not isinstance(g, dict):
            raise UserError(f"{src}: {key}.gpio: expected a mapping pin -> 0/1, e.g. {{0: 1}}")
        for pin, lvl in g.items():
            if isinstance(pin, bool) or not isinstance(pin, int) or not 0 <= pin <= 7:
                raise UserError(f"{src}: {key}.gpio: pin {pin!r}: expected 0..7")
            gpio[pin] = _level(src, f"{key}.gpio.{pin}", lvl)
    nes = _level(src, f"{key}.nes", d.get("nes", 1))
    return Wiring(stepper, encoder, tuple(spi), tuple(gpio), nes)


class Shaft:
    """A stepper motor and the encoder on its shaft: steps in, ABN transitions out.

    The motor moves ``microsteps_per_pulse`` microsteps per step pulse, positive while
    DIR is low (TMC8460 Table 145: DIR = 0 is the positive direction). The encoder count
    is floor(microsteps * counts_per_rev / microsteps_per_rev) plus what the shaft was
    turned by hand (:meth:`turn`; the only way it moves without a stepper)."""

    def __init__(self, stepper: StepperSpec | None, encoder: EncoderSpec | None) -> None:
        self.stepper = stepper
        self.encoder = encoder
        self.microsteps = 0
        self.turned = 0  # encoder counts turned by hand
        self.count = 0

    def count_at(self, microsteps: int) -> int:
        e, s = self.encoder, self.stepper
        if e is None:
            return 0
        motor = microsteps * e.counts_per_rev // s.microsteps_per_rev if s is not None else 0
        return motor + self.turned

    def levels(self, count: int) -> tuple[int, int, int]:
        """A, B, N at an encoder count: quadrature Gray code, N at count 0 of a turn."""
        a, b = ((0, 0), (1, 0), (1, 1), (0, 1))[count % 4]
        e = self.encoder
        n = 1 if e is not None and e.index and count % e.counts_per_rev == 0 else 0
        return a, b, n

    def move(self, pulses: int, unit: Encoder | None) -> None:
        """``pulses`` step pulses (signed); the encoder unit sees every transition."""
        if self.stepper is None:
            return
        self.microsteps += pulses * self.stepper.microsteps_per_pulse
        self._feed(unit)

    def turn(self, counts: int, unit: Encoder | None) -> None:
        """Turn the encoder by ``counts`` by hand."""
        self.turned += counts
        self._feed(unit)

    def _feed(self, unit: Encoder | None) -> None:
        new = self.count_at(self.microsteps)
        old = self.count
        self.count = new
        if unit is None or new == old or self.encoder is None:
            return
        step = 1 if new > old else -1
        cpr = self.encoder.counts_per_rev
        c = old
        while c != new:
            if self.encoder.index:
                # the next index count strictly beyond c in the direction of travel
                nxt = (c // cpr + 1) * cpr if step > 0 else ((c - 1) // cpr) * cpr
            else:
                nxt = new + step
            stop = nxt if (new - nxt) * step >= 0 else new
            # plain transitions up to (not onto) the index count, N inactive
            plain_end = stop - step if stop == nxt else stop
            k = plain_end - c
            if k:
                unit.run(k, 0)
                c = plain_end
            if c != new and stop == nxt:
                unit.run(step, 1)  # onto the index count: N active
                c = nxt
