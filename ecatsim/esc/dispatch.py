"""The register table compiled into the ESC's per-byte masks and hook tables.

A register row's ``side_effect: <unit>.<name>`` (``ecatsim/spec/registers.yaml``) names
the hooks of one of the ESC's units: the methods ``<prefix><name>`` of that unit's class.
The prefixes say when a hook runs:

- ``_ew_``: an ECAT write, every write (the write itself is the event: a command, a
  clear-on-write counter, the DC time loop);
- ``_ec_``: an ECAT write that changed a byte of the register (the hook depends on the
  value alone, so a broadcast that writes what is already there costs a copy, P20);
- ``_er_``: an ECAT read, before the bytes are taken;
- ``_pw_`` / ``_pr_``: a PDI write / read.

A hook is called as ``hook(unit, ra, rs, old)`` (writes; ``old`` is the register's value
before the write) or ``hook(unit, ra, rs)`` (reads), with the register's address and size.
The unit is found per call in ``Esc.units`` at the slot the side-effect bitmaps hold (slot
+ 1: a nonzero byte marks a hooked address). So a hooked register is a table row and a
method of its unit; nothing else names it. Ref: TMC8460 §4 Table 11, §5; decision U1.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ecatsim.esc.regs import (
    FMMU_BASE,
    FMMU_STRIDE,
    N_FMMU,
    N_SM,
    REGISTER_END,
    SM_BASE,
    SM_STRIDE,
)
from ecatsim.spec.tables import UNITS, Register, SpecError, load_registers

#: the slot of each unit in ``Esc.units``: the ESC, its DC, MII, EEPROM and watchdog
#: units, then its SyncManagers (a repeated ``sm.`` row acts on SM n: slot 5 + n)
SLOTS = {"esc": 0, "dc": 1, "mii": 2, "eeprom": 3, "wd": 4, "sm": 5}
N_SLOTS = 5 + N_SM
PREFIXES = ("_ew_", "_ec_", "_er_", "_pw_", "_pr_")

#: Side effects whose registers need no hook: the value is maintained by the unit that
#: owns it, or the function is absent on the TMC8460-BI (masks make it reserved).
PASSIVE_SIDE_EFFECTS = frozenset(
    {
        "esc.write_protect",  # not available with TMC8460-BI (§5.11-5.14)
        "esc.rw_offset",  # not available with TMC8460-BI (§5.18)
        "esc.led_override",  # not available with TMC8460-BI (§5.23, 5.24)
        "esc.al_status_code",  # plain PDI-written value (§5.22)
        "esc.ecat_event_request",  # maintained by the event logic (§5.31)
        "esc.al_event_request",  # maintained by the event logic (§5.32)
        "sm.status",  # maintained by the SyncManager (§5.49 Table 89)
        "dc.system_time_difference",  # maintained by the time loop (§5.50.2 Table 98)
        "dc.speed_counter_diff",  # maintained by the time loop (Table 100)
        "dc.latch_mode",  # plain value (Table 103)
        "dc.next_sync1",  # maintained by the SYNC unit (Table 111)
        "dc.latch_status",  # maintained by the latch unit (Tables 116, 117)
        "dc.event_time",  # maintained by the SM event-time logic (§5.50.6, sm_event_time)
        "esc.mfcio_parameter_ram",  # plain RAM the MFCIO block reads at its runs (§5.47)
        "esc.user_ram",  # plain RAM (§5.52)
    }
)
#: Register blocks whose ECAT write hook runs once per write of the block, with the
#: block's address and size: the six FMMUs (the hook recompiles them all at once, P20) and
#: the SyncManagers' channels (the windows are compiled once, P58)
WRITE_BLOCKS = {
    "esc.fmmu": (FMMU_BASE, N_FMMU * FMMU_STRIDE),
    "esc.sm": (SM_BASE, N_SM * SM_STRIDE),
    "esc.sm_activate": (SM_BASE, N_SM * SM_STRIDE),
}

Hook = Callable[..., None]
Entry = tuple[Hook, int, int]


@dataclass(frozen=True, slots=True)
class Tables:
    """The compiled register table: write masks, per-address side-effect bitmaps (slot + 1
    of the unit, 0: none), the change-only bitmap and the (hook, ra, rs) entries."""

    ecat_wmask: bytes
    pdi_wmask: bytes
    ecat_w_hooked: bytes
    ecat_w_change: bytes
    ecat_r_hooked: bytes
    pdi_w_hooked: bytes
    pdi_r_hooked: bytes
    ecat_w: tuple[Entry | None, ...]
    ecat_r: tuple[Entry | None, ...]
    pdi_w: tuple[Entry | None, ...]
    pdi_r: tuple[Entry | None, ...]
    resets: tuple[tuple[int, int, int], ...]


def _mask_bytes(rows: tuple[Register, ...], attr: str) -> bytes:
    out = bytearray(REGISTER_END)
    for r in rows:
        if not r.available:
            continue
        m = getattr(r, attr)
        out[r.addr : r.addr + r.size] = m.to_bytes(r.size, "little")
    return bytes(out)


def _check_units(classes: Mapping[str, type]) -> None:
    if set(classes) != UNITS or set(SLOTS) != UNITS:
        raise SpecError(f"the ESC's units {sorted(classes)} are not the table's {sorted(UNITS)}")


def compile_tables(classes: Mapping[str, type]) -> Tables:
    """Compile the register table into byte masks and per-address hook lists, the hooks
    looked up by name in ``classes`` (unit name -> the unit's class)."""
    _check_units(classes)
    rows = load_registers()
    maps: dict[str, list[Entry | None]] = {k: [None] * REGISTER_END for k in PREFIXES}
    bits = {k: bytearray(REGISTER_END) for k in PREFIXES}
    change = bytearray(REGISTER_END)
    for r in rows:
        if r.side_effect is None or not r.available:
            continue
        unit, _, name = r.side_effect.partition(".")
        slot = SLOTS[unit] + (r.index if unit == "sm" else 0)
        if hasattr(classes[unit], "_ew_" + name) and hasattr(classes[unit], "_ec_" + name):
            raise SpecError(f"{r.side_effect}: _ew_ (every write) or _ec_ (a change), not both")
        for prefix in PREFIXES:
            fn = getattr(classes[unit], prefix + name, None)
            if fn is None:
                continue
            ra, rs = (r.addr, r.size)
            if prefix in ("_ew_", "_ec_"):  # a block's write hook: once per write (P20)
                ra, rs = WRITE_BLOCKS.get(r.side_effect, (ra, rs))
            for a in range(r.addr, r.addr + r.size):
                maps[prefix][a] = (fn, ra, rs)
                bits[prefix][a] = slot + 1
                if prefix == "_ec_":
                    change[a] = 1
    ew = [e if e is not None else maps["_ec_"][a] for a, e in enumerate(maps["_ew_"])]
    return Tables(
        ecat_wmask=_mask_bytes(rows, "ecat_wmask"),
        pdi_wmask=_mask_bytes(rows, "pdi_wmask"),
        ecat_w_hooked=bytes(x | y for x, y in zip(bits["_ew_"], bits["_ec_"], strict=True)),
        ecat_w_change=bytes(change),
        ecat_r_hooked=bytes(bits["_er_"]),
        pdi_w_hooked=bytes(bits["_pw_"]),
        pdi_r_hooked=bytes(bits["_pr_"]),
        ecat_w=tuple(ew),
        ecat_r=tuple(maps["_er_"]),
        pdi_w=tuple(maps["_pw_"]),
        pdi_r=tuple(maps["_pr_"]),
        resets=tuple((r.addr, r.size, r.reset) for r in rows if r.available and r.reset),
    )


def hook_names(classes: Mapping[str, type]) -> set[str]:
    """``<unit>.<name>`` of every hook method of the units' classes."""
    out = set()
    for unit, cls in classes.items():
        for attr in dir(cls):
            for prefix in PREFIXES:
                if attr.startswith(prefix):
                    out.add(f"{unit}.{attr[len(prefix) :]}")
    return out
