"""Loaders for the datasheet and standard tables kept as YAML data in this package.

Ref: TMC8460 datasheet §4/§5 (registers.yaml); ETG.1000.6 Table 11 (AL status codes);
CiA 301 / ETG.1000.6 Table 41 (SDO abort codes); ETG.1000.4 (mailbox error codes).
"""

from __future__ import annotations

import importlib.resources
import itertools
import re
from dataclasses import dataclass
from functools import cache
from typing import Any

import yaml

#: The ESC's units a register row's ``side_effect`` may name, as ``<unit>.<name>``: the
#: ESC itself (addresses, reset, DL, AL, events, counters, FMMUs), the DC unit, the MII
#: management interface, the EEPROM interface, the process-data watchdog and the
#: SyncManagers (a repeated row names the n-th). The hooks are methods of the unit's class
#: (ecatsim/esc/dispatch.py). Ref: TMC8460 §4 Table 11, §5.
UNITS = frozenset({"esc", "dc", "mii", "eeprom", "wd", "sm"})
_NAME = re.compile(r"^[a-z][a-z0-9_]*$")

ACCESS = frozenset({"r", "rw", "-"})
_KEYS = {
    "addr",
    "size",
    "name",
    "ecat",
    "pdi",
    "reset",
    "ecat_wmask",
    "pdi_wmask",
    "side_effect",
    "available",
    "source",
    "note",
    "repeat",
}


class SpecError(ValueError):
    """A table row is malformed; the message names the row."""


@dataclass(frozen=True, slots=True)
class Register:
    """One register row (after expanding repeats)."""

    addr: int
    size: int
    name: str
    ecat: str
    pdi: str
    reset: int
    ecat_wmask: int
    pdi_wmask: int
    side_effect: str | None
    available: bool
    source: str
    note: str
    #: the repeat index (n of a ``{n}`` name), 0 for a single row: which of the unit's
    #: instances a repeated row's side effect acts on (the n-th SyncManager)
    index: int = 0

    @property
    def unit(self) -> str | None:
        """The unit the side effect names (``dc`` of ``dc.system_time``)."""
        return self.side_effect.partition(".")[0] if self.side_effect else None

    @property
    def hook(self) -> str | None:
        """The hook name within the unit (``system_time`` of ``dc.system_time``)."""
        return self.side_effect.partition(".")[2] if self.side_effect else None


@dataclass(frozen=True, slots=True)
class CodeRow:
    """One row of a code table (AL status, SDO abort, mailbox error)."""

    code: int
    name: str
    text: str
    source: str


def _read(name: str) -> str:
    return importlib.resources.files("ecatsim.spec").joinpath(name).read_text()


def _row(raw: Any, i: int) -> list[Register]:
    where = f"registers.yaml row {i}"
    if not isinstance(raw, dict):
        raise SpecError(f"{where}: expected a mapping")
    unknown = set(raw) - _KEYS
    if unknown:
        raise SpecError(f"{where}: unknown key {sorted(unknown)[0]!r}")
    for k in ("addr", "size", "name", "ecat", "pdi", "source"):
        if k not in raw:
            raise SpecError(f"{where}: missing {k!r}")
    name = raw["name"]
    where = f"registers.yaml row {i} ({name})"
    addr, size = raw["addr"], raw["size"]
    if not isinstance(addr, int) or not 0 <= addr < 0x1000:
        raise SpecError(f"{where}: addr must be 0x0000..0x0FFF")
    if not isinstance(size, int) or not 1 <= size <= 128:
        raise SpecError(f"{where}: size must be 1..128")
    ecat, pdi = raw["ecat"], raw["pdi"]
    if ecat not in ACCESS or pdi not in ACCESS:
        raise SpecError(f"{where}: access must be one of r, rw, -")
    full = (1 << (8 * size)) - 1
    ew = raw.get("ecat_wmask", full if ecat == "rw" else 0)
    pw = raw.get("pdi_wmask", full if pdi == "rw" else 0)
    for label, m in (("ecat_wmask", ew), ("pdi_wmask", pw)):
        if not isinstance(m, int) or not 0 <= m <= full:
            raise SpecError(f"{where}: {label} does not fit in {size} bytes")
    reset = raw.get("reset", 0)
    if not isinstance(reset, int) or not 0 <= reset <= full:
        raise SpecError(f"{where}: reset does not fit in {size} bytes")
    se = raw.get("side_effect")
    if se is not None:
        unit, _, hook = str(se).partition(".")
        if unit not in UNITS or not _NAME.match(hook):
            raise SpecError(
                f"{where}: unknown side_effect {se!r}: write <unit>.<name>, unit one of "
                + ", ".join(sorted(UNITS))
            )
    rep = raw.get("repeat") or {"count": 1, "stride": 0}
    count, stride = rep.get("count", 1), rep.get("stride", 0)
    out = []
    for n in range(count):
        out.append(
            Register(
                addr=addr + n * stride,
                size=size,
                name=str(name).replace("{n}", str(n)),
                ecat=ecat,
                pdi=pdi,
                reset=reset,
                ecat_wmask=ew,
                pdi_wmask=pw,
                side_effect=se,
                available=bool(raw.get("available", True)),
                source=str(raw["source"]),
                note=str(raw.get("note", "")),
                index=n,
            )
        )
    return out


def parse_registers(text: str) -> tuple[Register, ...]:
    """Parse and validate register-table YAML text."""
    data = yaml.safe_load(text)
    if not isinstance(data, dict) or not isinstance(data.get("registers"), list):
        raise SpecError("registers.yaml: expected a top-level 'registers:' list")
    rows: list[Register] = []
    for i, raw in enumerate(data["registers"]):
        rows.extend(_row(raw, i))
    rows.sort(key=lambda r: r.addr)
    for a, b in itertools.pairwise(rows):
        if a.addr + a.size > b.addr:
            raise SpecError(f"registers.yaml: {a.name} overlaps {b.name}")
    return tuple(rows)


@cache
def load_registers() -> tuple[Register, ...]:
    """The packaged TMC8460 register table, expanded and validated."""
    return parse_registers(_read("registers.yaml"))


@cache
def load_codes(name: str) -> dict[int, CodeRow]:
    """A packaged code table: al_status_codes, sdo_abort_codes or mailbox_errors."""
    data = yaml.safe_load(_read(f"{name}.yaml"))
    rows = data.get("codes") if isinstance(data, dict) else data
    if not isinstance(rows, list):
        raise SpecError(f"{name}.yaml: expected a list of codes")
    out = {}
    for r in rows:
        out[int(r["code"])] = CodeRow(
            int(r["code"]), str(r["name"]), str(r.get("text", "")), str(r.get("source", ""))
        )
    return out
