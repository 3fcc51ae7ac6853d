"""The units of the ESC that a register row's side effect may name (``<unit>.<name>``),
and the register table compiled against their classes, once (decision U1).
Ref: TMC8460 §5 (register table)."""

from __future__ import annotations

from functools import cache

from ecatsim.esc import dispatch
from ecatsim.esc.core import Esc
from ecatsim.esc.dc import DcUnit
from ecatsim.esc.dispatch import Tables, compile_tables
from ecatsim.esc.eeprom import EepromUnit
from ecatsim.esc.mii import MiiUnit
from ecatsim.esc.sm import SyncManager
from ecatsim.esc.watchdog import Watchdog


def unit_classes() -> dict[str, type]:
    """The class of each unit a register row's side effect may name."""
    return {
        "esc": Esc,
        "dc": DcUnit,
        "mii": MiiUnit,
        "eeprom": EepromUnit,
        "wd": Watchdog,
        "sm": SyncManager,
    }


@cache
def tables() -> Tables:
    """The register table compiled for the ESC (once): ecatsim/esc/dispatch.py."""
    return compile_tables(unit_classes())


def hook_names() -> set[str]:
    """``<unit>.<name>`` of the side effects that have at least one hook method."""
    return dispatch.hook_names(unit_classes())
