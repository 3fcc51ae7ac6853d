"""Faults as data: what a ``faults:`` entry of the segment YAML (or an ``inject`` request
on the control socket) may say, validated into a :class:`FaultSpec`.

One entry is flat::

    - kind: wkc            # what goes wrong (KINDS below)
      value: -1            # kind parameter (wkc delta, delay in us, ...)
      count: 3             # how many replies / times (default 1; see below)
      after_frames: 1000   # trigger: at once (nothing), after_frames, after_s, on_state
      for_s: 2.0           # optional: the fault lasts this long once started
      probability: 0.01    # optional: each frame fires with this probability ...
      seed: 7              # ... drawn from random.Random(seed): reproducible runs
      slave: 1             # target: a slave by position, or `alias: 0x1234`; port: 0/1

Ref: issue "reliability" (fault kinds and triggers); docs/decisions.md R1-R6.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Any

from ecatsim.slave.al import AlState


class Family(Enum):
    """How a kind acts once its trigger has fired."""

    WIRE = "wire"  # on each reply while live, ``count`` replies
    CONDITION = "condition"  # held while live, undone when the fault ends or is cleared
    ONCE = "once"  # one action per firing, ``count`` firings


@dataclass(frozen=True, slots=True)
class Kind:
    """One fault kind: its family, required and optional parameters."""

    family: Family
    params: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()
    needs_slave: bool = True


KINDS: dict[str, Kind] = {
    # wire faults on the reply (the whole frame); Ref: ETG.1000.4 §5.3-5.4
    "drop": Kind(Family.WIRE, needs_slave=False),
    "corrupt": Kind(Family.WIRE, needs_slave=False),
    "delay": Kind(Family.WIRE, ("value",), needs_slave=False),  # value: microseconds
    "duplicate": Kind(Family.WIRE, needs_slave=False),
    "wkc": Kind(Family.WIRE, ("value",), needs_slave=False),  # value: added to the WKC
    "circulating": Kind(Family.WIRE, needs_slave=False),
    # link faults; Ref: TMC8460 §5.19 (DL status), §5.38 (lost link counter)
    "link_down": Kind(Family.CONDITION, optional=("port",)),
    "power_cycle": Kind(Family.ONCE, optional=("value",)),  # value: ms without power
    # AL faults; Ref: ETG.1000.6 §6.4.1.4
    "al_refuse": Kind(Family.ONCE, ("code",)),
    "al_fall": Kind(Family.ONCE, ("code",)),
    # mailbox faults; Ref: ETG.1000.4 §5.6, ETG.1000.6 §5.6.2
    "mbx_drop": Kind(Family.ONCE),
    "sdo_abort": Kind(Family.ONCE, ("index", "code"), ("sub",)),
    "mbx_error": Kind(Family.ONCE, ("code",)),
    "mbx_counter": Kind(Family.ONCE),
    "sdo_toggle": Kind(Family.ONCE),
    # drive faults; Ref: issue "drive" (faults), CiA 402 §6.3 (fault reaction)
    "overcurrent": Kind(Family.CONDITION),
    "following_error": Kind(Family.CONDITION),
    "encoder_loss": Kind(Family.CONDITION),
    "overtemperature": Kind(Family.CONDITION),
}

STATES = {s.name.lower(): s for s in AlState}
TRIGGERS = ("after_frames", "after_s", "on_state")
FIELDS = frozenset(
    {"kind", "slave", "alias", "port", "value", "code", "index", "sub", "count", "for_s"}
    | {"probability", "seed", *TRIGGERS}
)


class FaultSpecError(ValueError):
    """A bad fault entry: ``field: problem (fix)``."""


@dataclass(frozen=True, slots=True)
class FaultSpec:
    """A validated fault. ``count`` None means unlimited (until it ends or is cleared)."""

    kind: str
    family: Family
    slave: int | None = None
    alias: int | None = None
    port: int = 1
    value: int = 0
    code: int = 0
    index: int = 0
    sub: int | None = None
    count: int | None = 1
    after_frames: int | None = None
    after_s: float | None = None
    on_state: AlState | None = None
    for_s: float | None = None
    probability: float | None = None
    seed: int = 0

    def describe(self) -> dict[str, Any]:
        """The fields that were set, for ``ctl status``."""
        out: dict[str, Any] = {"kind": self.kind}
        for name in ("slave", "alias", "after_frames", "after_s", "for_s", "probability"):
            v = getattr(self, name)
            if v is not None:
                out[name] = v
        if self.on_state is not None:
            out["on_state"] = self.on_state.name.lower()
        for name in ("value", "code", "index"):
            if getattr(self, name):
                out[name] = getattr(self, name)
        out["count"] = self.count
        return out


def _number(raw: dict[str, Any], key: str, lo: float, hi: float, kind: type) -> Any:
    """``raw[key]`` as an int or float within lo..hi (a string is parsed), or None."""
    v = raw.get(key)
    if v is None:
        return None
    name = "an integer" if kind is int else "a number"
    if isinstance(v, str):
        try:
            v = int(v, 0) if kind is int else float(v)
        except ValueError:
            raise FaultSpecError(f"{key}: expected {name}, got {v!r}") from None
    ok_type = isinstance(v, int) if kind is int else isinstance(v, int | float)
    if isinstance(v, bool) or not ok_type or not lo <= v <= hi:
        raise FaultSpecError(f"{key}: expected {name} {lo}..{hi}, got {v!r}")
    return kind(v)


def _int(raw: dict[str, Any], key: str, lo: int, hi: int) -> int | None:
    return _number(raw, key, lo, hi, int)  # type: ignore[no-any-return]


def _float(raw: dict[str, Any], key: str, lo: float, hi: float) -> float | None:
    return _number(raw, key, lo, hi, float)  # type: ignore[no-any-return]


def parse_fault(raw: object) -> FaultSpec:
    """Validate one fault entry. Raises FaultSpecError naming the field and the fix."""
    if not isinstance(raw, dict):
        raise FaultSpecError("expected a mapping like {kind: drop, after_frames: 100}")
    unknown = sorted(set(raw) - FIELDS)
    if unknown:
        raise FaultSpecError(f"{unknown[0]}: unknown field (allowed: {', '.join(sorted(FIELDS))})")
    name = raw.get("kind")
    kind = KINDS.get(str(name))
    if kind is None:
        raise FaultSpecError(f"kind: {name!r} is not a fault kind (use one of {', '.join(KINDS)})")
    for p in kind.params:
        if raw.get(p) is None:
            raise FaultSpecError(f"{p}: required for kind {name}")
    for p in ("value", "code", "index", "sub", "port"):
        if raw.get(p) is not None and p not in kind.params + kind.optional:
            raise FaultSpecError(f"{p}: not a parameter of kind {name}")
    triggers = [t for t in TRIGGERS if raw.get(t) is not None]
    if len(triggers) > 1:
        raise FaultSpecError(f"{triggers[1]}: give at most one of {', '.join(TRIGGERS)}")
    slave = _int(raw, "slave", 0, 0xFFFF)
    alias = _int(raw, "alias", 1, 0xFFFF)
    if slave is not None and alias is not None:
        raise FaultSpecError("alias: give either slave (a position) or alias, not both")
    if kind.needs_slave and slave is None and alias is None:
        slave = 0
    state = raw.get("on_state")
    on_state = None
    if state is not None:
        on_state = STATES.get(str(state).lower())
        if on_state is None:
            raise FaultSpecError(f"on_state: {state!r} is not a state (use {', '.join(STATES)})")
    for_s = _float(raw, "for_s", 0.0, 1e9)
    probability = _float(raw, "probability", 0.0, 1.0)
    count = _int(raw, "count", 0, 1 << 31)
    if count == 0 or (count is None and (for_s is not None or probability is not None)):
        count_out: int | None = None  # 0 or a window/probability without count: unlimited
    else:
        count_out = 1 if count is None else count
    value = _int(raw, "value", -0xFFFF, 10_000_000) or 0
    if name == "delay" and value <= 0:
        raise FaultSpecError("value: the delay in microseconds, > 0")
    if name == "power_cycle" and value < 0:
        raise FaultSpecError("value: the time without power in milliseconds, >= 0")
    port = _int(raw, "port", 0, 1)
    return FaultSpec(
        kind=str(name),
        family=kind.family,
        slave=slave,
        alias=alias,
        port=1 if port is None else port,
        value=value,
        code=_int(raw, "code", 0, 0xFFFFFFFF) or 0,
        index=_int(raw, "index", 0, 0xFFFF) or 0,
        sub=_int(raw, "sub", 0, 0xFF),
        count=count_out,
        after_frames=_int(raw, "after_frames", 0, 1 << 62),
        after_s=_float(raw, "after_s", 0.0, 1e9),
        on_state=on_state,
        for_s=for_s,
        probability=probability,
        seed=_int(raw, "seed", -(1 << 62), 1 << 62) or 0,
    )
