"""Twin process images for the layout tests (decisions P89, P95): one image with the C
layout tables, its twin without them (the struct and per-entry paths), both over the same
TMC8670 object dictionary and each RxPDO mapping it allows.

Ref: ETG.1000.6 §5.6.7.4 (PDO mapping), Table 64 (data types).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace

from ecatsim.device.description import default_description
from ecatsim.slave.od import Entry
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import Field, PdoImage, Plan, compile_plan
from tests.support.pdo_mappings import every_mapping, set_mapping


class Quiet:
    """A device that does nothing with the process data."""

    def outputs_applied(self, now_ns: int) -> None: ...

    def update_inputs(self, now_ns: int) -> None: ...

    def al_state_changed(self, state: object, now_ns: int) -> None: ...


def without_layout(plan: Plan) -> Plan:
    """``plan`` with neither codec's layout table: the struct and per-entry paths."""
    assert plan.rx_codec is not None and plan.tx_codec is not None
    return replace(
        plan,
        rx_codec=replace(plan.rx_codec, layout=None),
        tx_codec=replace(plan.tx_codec, layout=None),
    )


def value_range(e: Entry, size: int) -> tuple[int, int]:
    """The lowest and highest value of ``e`` in a field of ``size`` bytes."""
    bits = 8 * size
    if e.dtype.startswith("INTEGER"):
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    return 0, (1 << bits) - 1


def fits(fields: Iterable[Field]) -> bool:
    """Whether every mapped entry's value fits its field (an entry mapped twice holds one
    value, which may not fit its shorter field)."""
    for f in fields:
        if f.entry is not None:
            lo, hi = value_range(f.entry, f.size)
            if not (isinstance(f.entry.value, int) and lo <= f.entry.value <= hi):
                return False
    return True


@dataclass
class RxTwins:
    """The two images on one RxPDO mapping, and the output entries of each, in order."""

    mapping: object
    plan: Plan
    fast: PdoImage
    full: PdoImage
    fast_entries: list[Entry]
    full_entries: list[Entry]


def rx_twins() -> Iterator[RxTwins]:
    """For each RxPDO mapping the TMC8670 allows: the image with the layout (its plan's
    decoder has one) and its twin without, set to that mapping."""
    od_a, od_b = build_od(default_description()), build_od(default_description())
    fast, full = PdoImage(od_a, Quiet()), PdoImage(od_b, Quiet())
    for mapping in every_mapping(od_a, True):
        set_mapping(od_a, 0x1600, mapping)
        set_mapping(od_b, 0x1600, mapping)
        plan = compile_plan(od_a)
        assert plan.rx_codec is not None and plan.rx_codec.layout is not None
        fast.plan, full.plan = plan, without_layout(compile_plan(od_b))
        ea = [f.entry for f in plan.rx if f.entry is not None]
        eb = [f.entry for f in full.plan.rx if f.entry is not None]
        yield RxTwins(mapping, plan, fast, full, ea, eb)
