"""Build a device's object dictionary from its description: the communication objects
are generated from the identity, SMs and PDOs (never typed twice); the rest is the
description's object table (``od:`` file).
Ref: ETG.1000.6 §5.6.7 (communication area 0x1000-0x1FFF); TMC8670 §4, §5, §6-9.
"""

from __future__ import annotations

import importlib.resources
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from ecatsim.device.description import DescriptionError, DeviceDescription, PdoDescription
from ecatsim.slave.al import AlState
from ecatsim.slave.od import (
    IDENTITY_TYPE,
    PDO_MAPPING_TYPE,
    Entry,
    ObjectCode,
    ObjectDictionary,
    OdObject,
)

MAX_PDO_ENTRIES = 9  # TMC8670 §2.1: dynamic mapping with max. 9 entries
PREOP_ONLY = (int(AlState.PREOP),)


def _var(index: int, name: str, dtype: str, value: int | str, access: str = "ro") -> OdObject:
    e = Entry(0, name, dtype, access=access, default=value)
    return OdObject(index, name, ObjectCode.VAR, {0: e}, source="ETG.1000.6 §5.6.7")


def _pdo_mapping(index: int, pdo: PdoDescription | None, name: str) -> OdObject:
    entries = {
        0: Entry(
            0,
            "Number of mapped objects",
            "UNSIGNED8",
            access="rw",
            minimum=0,
            maximum=MAX_PDO_ENTRIES,
            default=len(pdo.entries) if pdo else 0,
            write_states=PREOP_ONLY,
        ),
    }
    for s in range(1, MAX_PDO_ENTRIES + 1):
        v = 0
        if pdo and s <= len(pdo.entries):
            pe = pdo.entries[s - 1]
            v = (pe.index << 16) | (pe.subindex << 8) | pe.bits
        entries[s] = Entry(
            s, f"Mapping entry {s}", "UNSIGNED32", access="rw", default=v, write_states=PREOP_ONLY
        )
    return OdObject(
        index,
        name,
        ObjectCode.RECORD,
        entries,
        source="TMC8670 §4.1.7/§4.1.8",
        record_type=PDO_MAPPING_TYPE,
    )


def _assign(index: int, pdo_index: int, name: str) -> OdObject:
    entries = {
        0: Entry(
            0,
            "Number of assigned PDOs",
            "UNSIGNED8",
            access="rw",
            minimum=0,
            maximum=1,
            default=1,
            write_states=PREOP_ONLY,
        ),
        1: Entry(
            1, "PDO assigned", "UNSIGNED16", access="rw", default=pdo_index, write_states=PREOP_ONLY
        ),
    }
    return OdObject(index, name, ObjectCode.ARRAY, entries, source="TMC8670 §4.1.10/§4.1.11")


def communication_objects(desc: DeviceDescription) -> list[OdObject]:
    """1008/1009/100A/1018/1600/1A00/1C00/1C12/1C13 from the description."""
    idn = desc.identity
    ident = OdObject(
        0x1018,
        "Identity object",
        ObjectCode.RECORD,
        {
            0: Entry(0, "Number of entries", "UNSIGNED8", default=3),
            1: Entry(1, "Vendor ID", "UNSIGNED32", default=idn.vendor_id),
            2: Entry(2, "Product code", "UNSIGNED32", default=idn.product_code),
            3: Entry(3, "Revision number", "UNSIGNED32", default=idn.revision),
        },
        source="TMC8670 §4.1.6 Tables 16, 17 (subindices 1-3; the serial is in the SII only)",
        record_type=IDENTITY_TYPE,
    )
    types = {"mbx_out": 1, "mbx_in": 2, "pd_out": 3, "pd_in": 4, "unused": 0}
    smt = {
        0: Entry(0, "Number of used sync managers", "UNSIGNED8", default=len(desc.sync_managers))
    }
    for i, sm in enumerate(desc.sync_managers):
        smt[i + 1] = Entry(i + 1, f"SM{i} communication type", "UNSIGNED8", default=types[sm.type])
    rx = desc.rxpdos[0] if desc.rxpdos else None
    tx = desc.txpdos[0] if desc.txpdos else None
    return [
        _var(0x1008, "Manufacturer device name", "VISIBLE_STRING", desc.name),
        _var(0x1009, "Manufacturer hardware version", "VISIBLE_STRING", desc.hardware_version),
        _var(0x100A, "Manufacturer software version", "VISIBLE_STRING", desc.software_version),
        ident,
        _pdo_mapping(0x1600, rx, "Receive PDO mapping"),
        _pdo_mapping(0x1A00, tx, "Transmit PDO mapping"),
        OdObject(
            0x1C00,
            "Sync manager communication type",
            ObjectCode.ARRAY,
            smt,
            source="TMC8670 §4.1.9, ETG.1000.6 §5.6.7.4.1",
        ),
        _assign(0x1C12, 0x1600, "Sync manager 2 PDO assignment"),
        _assign(0x1C13, 0x1A00, "Sync manager 3 PDO assignment"),
    ]


def _entry(raw: dict[str, Any], sub: int, where: str, fallback_type: str | None = None) -> Entry:
    dtype = raw.get("type", fallback_type)
    if not isinstance(dtype, str):
        raise DescriptionError(f"{where}: type missing")
    try:
        return Entry(
            sub,
            str(raw.get("name", f"Subindex {sub}")),
            dtype,
            access=str(raw.get("access", "ro")),
            pdo=bool(raw.get("pdo", False)),
            pdo_bits=tuple(int(b) for b in raw.get("pdo_bits", ())),
            minimum=raw.get("min"),
            maximum=raw.get("max"),
            default=raw.get("default", "" if "STRING" in dtype else 0),
            unit=str(raw.get("unit", "")),
            values=tuple(raw.get("values", ())),
        )
    except ValueError as exc:
        raise DescriptionError(f"{where}: {exc}") from exc


def table_objects(data: Any, src: str) -> list[OdObject]:
    """Objects from an ``objects:`` YAML table. Ref: the table's per-object ``source``."""
    rows = data.get("objects") if isinstance(data, dict) else None
    if not isinstance(rows, list):
        raise DescriptionError(f"{src}: expected an 'objects:' list")
    out = []
    for i, r in enumerate(rows):
        where = f"{src}: objects[{i}]"
        if not isinstance(r, dict) or not isinstance(r.get("index"), int):
            raise DescriptionError(f"{where}: expected a mapping with an integer index")
        index = r["index"]
        code = ObjectCode[str(r.get("code", "VAR"))]
        name = str(r.get("name", f"Object {index:04X}"))
        if code == ObjectCode.VAR:
            entries = {0: _entry(r, 0, f"{where} (0x{index:04X})")}
        else:
            entries = {}
            for j, e in enumerate(r.get("entries") or []):
                sub = int(e.get("sub", j + 1))
                if sub == 0:
                    entries[0] = _entry(e, 0, f"{where}.entries[{j}]", "UNSIGNED8")
                    continue
                entries[sub] = _entry(e, sub, f"{where}.entries[{j}]", r.get("type"))
            if 0 not in entries:
                entries[0] = Entry(
                    0, "Number of entries", "UNSIGNED8", default=max(entries) if entries else 0
                )
        out.append(
            OdObject(
                index,
                name,
                code,
                entries,
                source=str(r.get("source", "")),
                beyond_sheet=bool(r.get("beyond_sheet", False)),
            )
        )
    return out


@cache
def _parse_table_file(path: str, packaged: bool) -> Any:
    """Parse an object table once per process (slaves share it; values are per slave)."""
    if packaged:
        text = importlib.resources.files("ecatsim.defaults").joinpath(path).read_text()
    else:
        text = Path(path).read_text()
    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def load_od_table(desc: DeviceDescription, base: Path | None) -> list[OdObject]:
    """The description's ``od:`` section: ``{file: NAME}`` or an inline ``objects:`` list."""
    raw = desc.od_raw
    if raw is None:
        return []
    if isinstance(raw, dict) and "file" in raw:
        name = str(raw["file"])
        if base is not None and (base / name).exists():
            return table_objects(_parse_table_file(str(base / name), False), name)
        return table_objects(_parse_table_file(name, True), name)
    return table_objects(raw, desc.source)


def build_od(desc: DeviceDescription, base: Path | None = None) -> ObjectDictionary:
    """The full object dictionary of one slave."""
    objs = {o.index: o for o in load_od_table(desc, base)}
    for o in communication_objects(desc):
        objs[o.index] = o
    return ObjectDictionary(list(objs.values()))
