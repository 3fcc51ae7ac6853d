"""Process data a test can drive: every mapped entry of a CoE slave's process image, by
``0xIIII:SS`` or name; inputs take values, outputs are read.

Names: ``PDO/Entry`` (the mapping object's name and the entry's), an entry name that is
unique among the mapped entries, or a PDO's name when it maps one entry.
Ref: ETG.1000.6 §5.6.7.4 (PDO mapping and assignment: what the image holds).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ecatsim.slave.od import Entry, ObjectDictionary
from ecatsim.slave.pdo import RX_ASSIGN, TX_ASSIGN, PdoImage, assigned


@dataclass(frozen=True, slots=True)
class Mapped:
    """One entry of the process image."""

    index: int
    sub: int
    name: str
    pdo: int
    pdo_name: str
    output: bool
    bits: int
    entry: Entry

    def as_dict(self) -> dict[str, Any]:
        v = self.entry.value
        return {
            "entry": f"0x{self.index:04X}:{self.sub:02X}",
            "name": self.name,
            "pdo": f"0x{self.pdo:04X}",
            "pdo_name": self.pdo_name,
            "direction": "output" if self.output else "input",
            "bits": self.bits,
            "value": v.hex() if isinstance(v, bytes) else v,
        }


def mapped(od: ObjectDictionary) -> list[Mapped]:
    """The entries the assigned PDOs map now, outputs first, in image order."""
    out = []
    for assign, output in ((RX_ASSIGN, True), (TX_ASSIGN, False)):
        for p in assigned(od, assign):
            if p not in od:
                continue
            obj = od[p]
            for s in range(1, int(obj.entries[0].value) + 1):
                v = int(obj.entries[s].value)
                index, sub, bits = v >> 16, (v >> 8) & 0xFF, v & 0xFF
                if index == 0 or index not in od or sub not in od[index].entries:
                    continue
                o = od[index]
                e = o.entries[sub]
                name = o.name if sub == 0 else e.name
                out.append(Mapped(index, sub, name, p, obj.name, output, bits, e))
    return out


def _hex_entry(text: str) -> tuple[int, int] | None:
    t = text.strip()
    if not t.lower().startswith("0x"):
        return None
    i, sep, s = t.partition(":")
    try:
        return int(i, 16), int(s, 16) if sep else 0
    except ValueError:
        return None


def find(od: ObjectDictionary, text: str, *, mapped_only: bool = False) -> Mapped | Entry:
    """The entry ``text`` names: ``0xIIII:SS`` (subindex in hex) or a name (see above)."""
    fields = mapped(od)
    hx = _hex_entry(text)
    if hx is not None:
        for m in fields:
            if (m.index, m.sub) == hx:
                return m
        if mapped_only:
            raise ValueError(f"{text}: not mapped in the process image")
        return od.entry(*hx)
    t = text.strip()
    for test in (
        lambda m: f"{m.pdo_name}/{m.name}" == t,
        lambda m: m.name == t,
        lambda m: m.pdo_name == t,
    ):
        hits = [m for m in fields if test(m)]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            names = ", ".join(f"0x{m.index:04X}:{m.sub:02X}" for m in hits)
            raise ValueError(f"{text!r} names several entries ({names}): use 0xIIII:SS")
    raise ValueError(f"{text!r}: no mapped entry of that name (see 'ecatsim ctl pd SLAVE')")


def _value(m: Mapped, value: Any) -> int | str:
    if isinstance(value, str):
        try:
            return int(value, 0)
        except ValueError:
            return value
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if not isinstance(value, int):
        raise ValueError(f"{value!r}: expected an integer")
    return value


def request(app: object, req: dict[str, Any]) -> dict[str, Any]:
    """The control socket's ``pd`` command: list, read one entry, or set an input."""
    if not isinstance(app, PdoImage):
        raise ValueError("this slave has no CoE process image (ctl pd needs one)")
    od = app.od
    if od.refresh is not None:
        od.refresh()
    entry = req.get("entry")
    if entry is None:
        return {"ok": True, "entries": [m.as_dict() for m in mapped(od)]}
    m = find(od, str(entry), mapped_only=True)
    assert isinstance(m, Mapped)
    if "value" in req:
        if m.output:
            raise ValueError(
                f"{entry}: an output (RxPDO 0x{m.pdo:04X}): the master writes it; set inputs"
            )
        m.entry.value = _value(m, req["value"])
    return {"ok": True, **m.as_dict()}


def format_entries(entries: list[dict[str, Any]]) -> str:
    """``ctl pd``'s answer for people: one entry a line."""
    rows = [["entry", "dir", "bits", "value", "name", "pdo"]]
    for e in entries:
        v = e["value"]
        value = (
            f"{v} (0x{v & 0xFFFFFFFFFFFFFFFF:X})"
            if isinstance(v, int) and not -10 < v < 10
            else str(v)
        )
        rows.append([e["entry"], e["direction"][:3], str(e["bits"]), value, e["name"],
                     f"{e['pdo']} {e['pdo_name']}"])  # fmt: skip
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )
