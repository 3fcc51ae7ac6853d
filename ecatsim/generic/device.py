"""The device behind a generic slave's firmware: its inputs hold what a test or a
``signals:`` item put there; its outputs hold what the master wrote.

Ref: ETG.1000.6 §6.4 (the application behind the AL state machine); §5.6.7.4 (the
process data objects it works on).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ecatsim.generic.signals import Signal, SignalError, make_signal
from ecatsim.slave.al import AlState
from ecatsim.slave.od import Entry, ObjectDictionary, SdoAbort
from ecatsim.slave.pd import Mapped, find


class GenericDevice:
    """A CoeDevice (ecatsim/slave/pdo.py) that only moves data."""

    def __init__(self, od: ObjectDictionary, signals: list[Signal] | None = None) -> None:
        self.od = od
        self.signals = signals or []
        self.t0: int | None = None
        self.state = AlState.INIT
        self.cycles = 0

    def outputs_applied(self, now_ns: int) -> None:
        self.cycles += 1

    def update_inputs(self, now_ns: int) -> None:
        """The signals, on the slave's simulated time since its first inputs."""
        if not self.signals:
            return
        if self.t0 is None:
            self.t0 = now_ns
        t = now_ns - self.t0
        for s in self.signals:
            s.apply(t)

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        self.state = state


def signals_of(raw: Any, od: ObjectDictionary, where: str) -> list[Signal]:
    """A slave's ``signals:`` list against its OD (one-line SignalError otherwise)."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise SignalError(f"{where}: expected a list like [{{input: ENTRY, counter: {{}}}}]")

    def resolver(where_i: str) -> Callable[[str], Entry]:
        def resolve(text: str) -> Entry:
            try:
                hit = find(od, text)
            except (ValueError, SdoAbort) as exc:
                msg = str(exc) if isinstance(exc, ValueError) else f"no entry {text} in the OD"
                raise SignalError(f"{where_i}: {msg}") from None
            return hit.entry if isinstance(hit, Mapped) else hit

        return resolve

    return [
        make_signal(item, f"{where}[{i}]", resolver(f"{where}[{i}]")) for i, item in enumerate(raw)
    ]
