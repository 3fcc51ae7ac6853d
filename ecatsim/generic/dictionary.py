"""An ESI's <Profile><Dictionary> as OD objects: data types (base, arrays, records, enums,
strings), objects with defaults (DefaultData/DefaultValue/DefaultString), limits, access
per state and PDO mappability.

What is not modelled is a warning naming the construct, never an exception: an object
that cannot be read is left out with a warning.
Ref: ETG.2000 §5 (Profile/Dictionary: DataTypes, Objects, Info, Flags); ETG.1000.6
§5.6.3 (SDO Information access bits), Table 63 (data types).
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from ecatsim.generic.types import base_type, by_bits
from ecatsim.slave.al import AlState
from ecatsim.slave.od import Entry, ObjectCode, OdObject

_P, _S, _O = int(AlState.PREOP), int(AlState.SAFEOP), int(AlState.OP)
#: ETG.2000 Access WriteRestrictions -> the AL states a write is allowed in
WRITE_STATES: dict[str, tuple[int, ...]] = {
    "PreOP": (_P,),
    "SafeOP": (_S,),
    "OP": (_O,),
    "PreOP_SafeOP": (_P, _S),
    "PreOP_OP": (_P, _O),
    "SafeOP_OP": (_S, _O),
}


def num(text: str | None) -> int:
    """An ESI number: ``#x1A00``, ``0x1A00`` or decimal (ValueError otherwise)."""
    t = (text or "").strip()
    if t.startswith("#x"):
        return int(t[2:], 16)
    return int(t, 0)


def _text(el: ET.Element | None, tag: str) -> str | None:
    if el is None:
        return None
    c = el.find(tag)
    return None if c is None or c.text is None else c.text.strip()


@dataclass(frozen=True, slots=True)
class _Flags:
    access: str = "ro"
    write_states: tuple[int, ...] = ()
    pdo: bool = False


def _flags(el: ET.Element | None, default: _Flags, warn: set[str]) -> _Flags:
    f = el.find("Flags") if el is not None else None
    if f is None:
        return default
    access, states, pdo = default.access, default.write_states, default.pdo
    a = f.find("Access")
    if a is not None and a.text:
        access = a.text.strip().lower()
        if access not in ("ro", "rw", "wo"):
            warn.add(f"Access {a.text.strip()!r} (read as ro)")
            access = "ro"
        wr = a.get("WriteRestrictions")
        states = ()
        if wr:
            if wr in WRITE_STATES:
                states = WRITE_STATES[wr]
            else:
                warn.add(f"WriteRestrictions {wr!r}")
        if a.get("ReadRestrictions"):
            warn.add("ReadRestrictions (reads allowed in every state)")
    pm = _text(f, "PdoMapping")
    if pm is not None:
        pdo = pm.upper() in ("R", "T", "RT", "TR")
    return _Flags(access, states, pdo)


@dataclass(frozen=True, slots=True)
class _Item:
    """One entry to make: subindex, name, type, bits, flags."""

    sub: int
    name: str
    dtype: str
    bits: int
    flags: _Flags


class Dictionary:
    """The DataTypes of one ESI Dictionary, resolving type names."""

    def __init__(self, dic: ET.Element, warn: set[str]) -> None:
        self.warn = warn
        self.types: dict[str, ET.Element] = {}
        for dt in dic.findall("DataTypes/DataType"):
            name = _text(dt, "Name")
            if name:
                self.types[name] = dt

    def scalar(self, tname: str, bits: int) -> tuple[str, int]:
        """(OD type, bits) of a type that is one value (base, enum, string, byte array)."""
        bt = base_type(tname, bits)
        if bt is not None:
            return bt[0], bt[1] or bits
        dt = self.types.get(tname)
        if dt is not None:
            size = int(_text(dt, "BitSize") or bits or 0)
            base = _text(dt, "BaseType")
            if dt.find("EnumInfo") is not None:  # an enum: its base type's values
                b = base_type(base, size) if base else None
                return (b[0], size) if b else (by_bits(size), size)
            if dt.find("ArrayInfo") is not None:  # an array used as one value: bytes
                return "OCTET_STRING", size
            if base:
                b = base_type(base, size)
                if b is not None:
                    return b[0], size or b[1]
        self.warn.add(f"data type {tname!r} (read as {by_bits(bits)})")
        return by_bits(bits), bits

    def items(self, tname: str, bits: int, flags: _Flags) -> tuple[ObjectCode, list[_Item]]:
        """The entries of an object of type ``tname``."""
        dt = self.types.get(tname)
        subs = dt.findall("SubItem") if dt is not None else []
        if not subs:
            d, b = self.scalar(tname, bits)
            return ObjectCode.VAR, [_Item(0, "", d, b, flags)]
        out: list[_Item] = []
        code = ObjectCode.RECORD
        next_sub = 0
        for si in subs:
            sname = _text(si, "Name") or ""
            stype = _text(si, "Type") or ""
            sbits = int(_text(si, "BitSize") or 0)
            sflags = _flags(si, flags, self.warn)
            sub_txt = _text(si, "SubIdx")
            sub = num(sub_txt) if sub_txt else next_sub
            arr = self.types.get(stype)
            info = arr.find("ArrayInfo") if arr is not None else None
            if arr is not None and info is not None and not arr.findall("SubItem"):
                # the elements of an ARRAY object: subindex LBound.. of the base type
                lb = int(_text(info, "LBound") or 1)
                n = int(_text(info, "Elements") or 0)
                base = _text(arr, "BaseType") or ""
                ebits = (sbits // n) if n else 0
                d, b = self.scalar(base, ebits)
                for k in range(n):
                    out.append(_Item(lb + k, f"SubIndex {lb + k:03d}", d, b, sflags))
                next_sub = lb + n
                if len(subs) <= 2:
                    code = ObjectCode.ARRAY
                continue
            if arr is not None and arr.findall("SubItem"):
                self.warn.add(f"nested record type {stype!r} (read as bytes)")
                out.append(_Item(sub, sname, "OCTET_STRING", sbits, sflags))
            else:
                d, b = self.scalar(stype, sbits)
                out.append(_Item(sub, sname, d, b, sflags))
            next_sub = sub + 1
        return code, out


def _default(e: Entry, info: ET.Element | None, warn: set[str], where: str) -> None:
    """Set an entry's default from <Info>: DefaultData (little-endian hex), DefaultValue,
    DefaultString; MinValue/MaxValue as its limits (integers). What is not a number is a
    warning naming the entry; the entry keeps 0 / no limit."""
    if info is None:
        return
    data = _text(info, "DefaultData")
    value = _text(info, "DefaultValue")
    string = _text(info, "DefaultString")
    v: int | str | bytes | None = None
    try:
        if data is not None:
            raw = bytes.fromhex(data)
            if e.is_string:
                v = raw.decode("latin-1") if e.dtype == "VISIBLE_STRING" else raw
            else:
                n = (e.bits + 7) // 8
                v = e.decode(raw[:n].ljust(n, b"\x00"))
        elif string is not None:
            v = string
        elif value is not None:
            v = _value(e, value)
    except ValueError:
        warn.add(f"{where}: default {data or value!r} is not a number")
    if v is not None:
        e.default = v if not isinstance(v, bytes) else v.hex()
        e.value = v
    if e.is_string or e.dtype in ("REAL32", "REAL64"):
        return
    for tag in ("MinValue", "MaxValue"):
        t = _text(info, tag)
        if t is None:
            continue
        try:
            if tag == "MinValue":
                e.minimum = num(t)
            else:
                e.maximum = num(t)
        except ValueError:
            warn.add(f"{where}: {tag} {t!r} is not a number (no limit)")


def _value(e: Entry, text: str) -> int | str:
    if e.is_string:
        return text
    if e.dtype == "REAL32" and not text.startswith("#x"):
        return int(struct.unpack("<I", struct.pack("<f", float(text)))[0])
    if e.dtype == "REAL64" and not text.startswith("#x"):
        return int(struct.unpack("<Q", struct.pack("<d", float(text)))[0])
    return num(text)


def _entry(item: _Item, name: str) -> Entry:
    f = item.flags
    return Entry(
        item.sub,
        name or item.name or f"SubIndex {item.sub:03d}",
        item.dtype,
        access=f.access,
        pdo=f.pdo,
        write_states=f.write_states if f.access != "ro" else (),
        default="" if item.dtype in ("VISIBLE_STRING", "UNICODE_STRING") else 0,
        bits=item.bits if item.dtype != "BOOLEAN" else 1,
    )


def read_objects(dic: ET.Element, where: str, warn: set[str]) -> list[OdObject]:
    """Every <Object> of a Dictionary that can be read; the rest are warnings."""
    types = Dictionary(dic, warn)
    out: list[OdObject] = []
    for i, ob in enumerate(dic.findall("Objects/Object")):
        try:
            index = num(_text(ob, "Index"))
        except ValueError:
            warn.add(f"<Object> #{i + 1} without a readable <Index> (left out)")
            continue
        try:
            out.append(_object(types, ob, index, f"{where} object 0x{index:04X}", warn))
        except (ValueError, KeyError, struct.error) as exc:
            warn.add(f"object 0x{index:04X} ({exc}; left out)")
    return out


def _object(types: Dictionary, ob: ET.Element, index: int, where: str, warn: set[str]) -> OdObject:
    name = _text(ob, "Name") or f"Object 0x{index:04X}"
    tname = _text(ob, "Type") or ""
    bits = int(_text(ob, "BitSize") or 0)
    flags = _flags(ob, _Flags(), warn)
    code, items = types.items(tname, bits, flags)
    info = ob.find("Info")
    entries: dict[int, Entry] = {}
    if code == ObjectCode.VAR:
        e = _entry(items[0], name)
        _default(e, info, warn, f"object 0x{index:04X}")
        entries[0] = e
        return OdObject(index, name, code, entries, source=where)
    infos = info.findall("SubItem") if info is not None else []
    by_name: dict[str, ET.Element] = {}
    for si in infos:
        n = _text(si, "Name")
        if n and n not in by_name:
            by_name[n] = si
    positional = len(infos) == len(items)
    for k, item in enumerate(items):
        e = _entry(item, item.name)
        sub_info = infos[k] if positional else by_name.get(item.name)
        info_el = sub_info.find("Info") if sub_info is not None else None
        _default(e, info_el, warn, f"object 0x{index:04X}:{item.sub:02X}")
        entries[item.sub] = e
    if 0 not in entries:
        entries[0] = Entry(0, "Number of entries", "UNSIGNED8", default=max(entries))
    if entries[0].dtype != "UNSIGNED8":
        v0 = entries[0].value
        entries[0] = Entry(
            0, entries[0].name, "UNSIGNED8", default=v0 if isinstance(v0, int) else 0
        )
    return OdObject(index, name, code, entries, source=where)
