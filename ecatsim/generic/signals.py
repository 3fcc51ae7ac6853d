"""Behaviour for a generic slave's inputs without a test attached (``signals:``).

Each signal sets one input entry from the slave's simulated time (the ``now_ns`` its
firmware runs on), when the inputs are produced:

```yaml
signals:
  - {input: "0x6000:01", loopback: "0x7000:01"}   # the output's value
  - {input: Counter, counter: {step: 1, period_ms: 1}}
  - {input: "0x6010:11", sine: {amplitude: 1000, period_ms: 100, offset: 0}}
  - {input: Status, square: {amplitude: 1, period_ms: 50, offset: 0}}
  - {input: Limit, constant: 42}
```

ENTRY is ``0xIIII:SS`` or an entry's name (see ecatsim/slave/pd.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ecatsim.slave.od import Entry

KINDS = ("loopback", "counter", "sine", "square", "constant")
NS_PER_MS = 1_000_000


class SignalError(ValueError):
    """A bad ``signals:`` item: one line naming the key."""


@dataclass
class Signal:
    """One input driven by a function of time (ns since the slave's first inputs)."""

    target: Entry
    fn: Callable[[int], int]

    def apply(self, t_ns: int) -> None:
        self.target.value = self.fn(t_ns)


def _num(d: dict[str, Any], key: str, where: str, default: float | None = None) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise SignalError(f"{where}.{key}: expected a number, got {v!r}")
    return float(v)


def _params(raw: Any, where: str, allowed: set[str]) -> dict[str, Any]:
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise SignalError(f"{where}: expected a mapping like {{period_ms: 100}}")
    bad = set(raw) - allowed
    if bad:
        raise SignalError(
            f"{where}.{sorted(bad)[0]}: unknown key (use: {', '.join(sorted(allowed))})"
        )
    return raw


def make_signal(raw: Any, where: str, resolve: Callable[[str], Entry]) -> Signal:
    """One ``signals:`` item; ``resolve`` finds an entry by ``0xIIII:SS`` or name."""
    if not isinstance(raw, dict) or "input" not in raw:
        raise SignalError(f"{where}: expected a mapping like {{input: ENTRY, counter: {{}}}}")
    kinds = [k for k in raw if k in KINDS]
    bad = set(raw) - {"input", *KINDS}
    if bad:
        raise SignalError(
            f"{where}.{sorted(bad)[0]}: unknown key (use input and one of: {', '.join(KINDS)})"
        )
    if len(kinds) != 1:
        raise SignalError(f"{where}: give exactly one of: {', '.join(KINDS)}")
    kind = kinds[0]
    target = resolve(str(raw["input"]))
    arg = raw[kind]
    w = f"{where}.{kind}"
    if kind == "loopback":
        source = resolve(str(arg))

        def loop(_t: int) -> int:
            v = source.value
            return int(v) if isinstance(v, int | float) else 0

        return Signal(target, loop)
    if kind == "constant":
        if isinstance(arg, bool) or not isinstance(arg, int):
            raise SignalError(f"{w}: expected an integer, got {arg!r}")
        value = int(arg)
        return Signal(target, lambda _t: value)
    p = _params(arg, w, {"period_ms", "step", "amplitude", "offset"})
    period = _num(p, "period_ms", w, 1.0 if kind == "counter" else 1000.0)
    if period <= 0:
        raise SignalError(f"{w}.period_ms: expected a number > 0")
    period_ns = period * NS_PER_MS
    if kind == "counter":
        step = int(_num(p, "step", w, 1))
        return Signal(target, lambda t: int(t // period_ns) * step)
    amp = _num(p, "amplitude", w, 1.0)
    off = _num(p, "offset", w, 0.0)
    if kind == "sine":
        return Signal(
            target, lambda t: round(off + amp * math.sin(2 * math.pi * (t % period_ns) / period_ns))
        )
    return Signal(target, lambda t: round(off + (amp if (t % period_ns) < period_ns / 2 else 0)))
