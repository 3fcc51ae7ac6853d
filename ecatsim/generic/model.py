"""A generic slave's model: its description (for the SII), a maker of its object
dictionary (one per slave: values are per slave) and its PDO rules.

Sources: an ESI device (``from_esi``); the ENI builds the same model (ecatsim/ethercat/eni.py).
The communication objects an ESI leaves out are made from its PDOs and SMs:
0x1000, 0x1008, 0x1018, 0x1C00, 0x16xx/0x1Axx (entries from <RxPdo>/<TxPdo>), and
0x1C12/0x1C13 holding the PDOs the ESI assigns by default (those with an ``Sm``).
Ref: ETG.2000 §5 (Device: RxPdo/TxPdo Fixed, Mandatory, Sm, Exclude; Profile/Dictionary);
ETG.1000.6 §5.6.7 (communication area), §5.6.7.4 (PDO mapping and assignment).
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ecatsim.device.description import DeviceDescription, PdoDescription, PdoEntry
from ecatsim.device.esi import EsiError, read_esi_device
from ecatsim.generic.dictionary import num, read_objects
from ecatsim.generic.types import pdo_entry_type
from ecatsim.slave.al import AlState
from ecatsim.slave.od import Entry, ObjectCode, ObjectDictionary, OdObject
from ecatsim.slave.pdo import RX_ASSIGN, TX_ASSIGN, PdoRules

#: an SM number that is no SM: a PDO the ESI does not assign by default (SII PDO
#: category byte 2). Ref: ETG.2010 Table 14.
NO_SM = 0xFF
#: configurable PDOs get room for this many entries at least (ETG.2000 gives no number)
MIN_CONFIGURABLE_ENTRIES = 8
PREOP_ONLY = (int(AlState.PREOP),)
#: SII word 0 bit 8 = register 0x0141 bit 0. Ref: ETG.2010 Table 2; TMC8460 §5.26.
DEVICE_EMULATION = 0x0100
#: a generic PDO is at most one SM's worth of bytes (ESC SM length register, 16 bit)
MAX_BITS = 0xFFFF * 8
#: ESI constructs ecatsim does not model, warned about by name when present
UNMODELLED = (
    "Slots",
    "Modules",
    "Mailbox/SoE",
    "Mailbox/AoE",
    "Mailbox/VoE",
    "Dc/OpMode/Sm",
)


@dataclass(frozen=True, slots=True)
class PdoSpec:
    """One PDO as the ESI (or ENI) describes it."""

    pdo: PdoDescription
    assigned: bool
    fixed: bool = False
    mandatory: bool = False
    exclude: frozenset[int] = frozenset()


@dataclass
class GenericModel:
    """Everything needed to build one more slave of this kind."""

    desc: DeviceDescription
    rx: tuple[PdoSpec, ...]
    tx: tuple[PdoSpec, ...]
    #: reads the Dictionary's objects afresh (None: the ESI has no Dictionary)
    dictionary: Callable[[set[str]], list[OdObject]] | None
    warnings: list[str] = field(default_factory=list)
    #: PDO assignment writable (CoE PdoAssign, or alternatives to choose from)
    assign_writable: bool = True
    source: str = ""

    @property
    def rules(self) -> PdoRules:
        excl: dict[int, frozenset[int]] = {}
        for s in (*self.rx, *self.tx):
            if s.exclude:
                excl[s.pdo.index] = s.exclude
        return PdoRules(
            rx_pdos=tuple(s.pdo.index for s in self.rx),
            tx_pdos=tuple(s.pdo.index for s in self.tx),
            max_bits=MAX_BITS,
            bit_mapping=True,
            mandatory=frozenset(s.pdo.index for s in (*self.rx, *self.tx) if s.mandatory),
            exclude=excl,
        )

    def build_od(self) -> ObjectDictionary:
        """A fresh object dictionary for one slave."""
        objs: dict[int, OdObject] = {}
        if self.dictionary is not None:
            for o in self.dictionary(set()):
                objs[o.index] = o
        for o in self._communication(objs):
            objs.setdefault(o.index, o)
        for specs, rx in ((self.rx, True), (self.tx, False)):
            for s in specs:
                objs[s.pdo.index] = self._mapping(objs.get(s.pdo.index), s)
                for e in s.pdo.entries:
                    _ensure_mapped(objs, e, rx)
        for index, specs in ((RX_ASSIGN, self.rx), (TX_ASSIGN, self.tx)):
            objs[index] = self._assign(objs.get(index), index, specs)
        return ObjectDictionary(list(objs.values()))

    def _communication(self, have: dict[int, OdObject]) -> list[OdObject]:
        d = self.desc
        idn = d.identity
        out = [
            OdObject(0x1000, "Device type", ObjectCode.VAR,
                     {0: Entry(0, "Device type", "UNSIGNED32", default=0)}),
            OdObject(0x1008, "Device name", ObjectCode.VAR,
                     {0: Entry(0, "Device name", "VISIBLE_STRING", default=d.name)}),
            OdObject(0x1018, "Identity", ObjectCode.RECORD, {
                0: Entry(0, "Number of entries", "UNSIGNED8", default=4),
                1: Entry(1, "Vendor ID", "UNSIGNED32", default=idn.vendor_id),
                2: Entry(2, "Product code", "UNSIGNED32", default=idn.product_code),
                3: Entry(3, "Revision", "UNSIGNED32", default=idn.revision),
                4: Entry(4, "Serial number", "UNSIGNED32", default=idn.serial),
            }),
        ]  # fmt: skip
        if 0x1C00 not in have:
            types = {"mbx_out": 1, "mbx_in": 2, "pd_out": 3, "pd_in": 4, "unused": 0}
            smt = {0: Entry(0, "Number of entries", "UNSIGNED8", default=len(d.sync_managers))}
            for i, sm in enumerate(d.sync_managers):
                smt[i + 1] = Entry(i + 1, f"SubIndex {i + 1:03d}", "UNSIGNED8",
                                   default=types[sm.type])  # fmt: skip
            out.append(OdObject(0x1C00, "Sync manager type", ObjectCode.ARRAY, smt))
        return out

    def _mapping(self, have: OdObject | None, s: PdoSpec) -> OdObject:
        """0x16xx/0x1Axx: the Dictionary's object where it has one, holding the PDO's
        entries; fixed PDOs read-only, the others writable in PREOP."""
        p = s.pdo
        values = [(e.index << 16) | (e.subindex << 8) | e.bits for e in p.entries]
        n = len(values) if s.fixed else max(len(values), MIN_CONFIGURABLE_ENTRIES)
        access = "ro" if s.fixed else "rw"
        states = () if s.fixed else PREOP_ONLY
        if have is not None and have.code != ObjectCode.VAR and have.max_sub >= len(values):
            n = have.max_sub
        entries = {
            0: Entry(0, "Number of entries", "UNSIGNED8", access=access, minimum=0, maximum=n,
                     default=len(values), write_states=states),
        }  # fmt: skip
        for k in range(1, n + 1):
            old = have.entries.get(k) if have is not None else None
            entries[k] = Entry(
                k,
                old.name if old is not None else f"SubIndex {k:03d}",
                "UNSIGNED32",
                access=access,
                default=values[k - 1] if k <= len(values) else 0,
                write_states=states,
            )
        return OdObject(p.index, p.name or (have.name if have else ""), ObjectCode.RECORD,
                        entries, source=self.source)  # fmt: skip

    def _assign(self, have: OdObject | None, index: int, specs: tuple[PdoSpec, ...]) -> OdObject:
        """0x1C12/0x1C13: the default-assigned PDOs, room for all the SM may carry."""
        pdos = [s.pdo.index for s in specs if s.assigned]
        n = max(len(specs), 1)
        if have is not None and have.code != ObjectCode.VAR:
            n = max(n, have.max_sub)
        access = "rw" if self.assign_writable else "ro"
        states = PREOP_ONLY if self.assign_writable else ()
        entries = {
            0: Entry(0, "Number of entries", "UNSIGNED8", access=access, minimum=0, maximum=n,
                     default=len(pdos), write_states=states),
        }  # fmt: skip
        for k in range(1, n + 1):
            entries[k] = Entry(k, f"SubIndex {k:03d}", "UNSIGNED16", access=access,
                               default=pdos[k - 1] if k <= len(pdos) else 0,
                               write_states=states)  # fmt: skip
        name = have.name if have is not None else f"Sync manager {index - 0x1C10} PDO assignment"
        return OdObject(index, name, ObjectCode.ARRAY, entries, source=self.source)


def _ensure_mapped(objs: dict[int, OdObject], pe: PdoEntry, rx: bool) -> None:
    """A PDO entry's object exists and is mappable with its bit length (made from the PDO
    entry where the Dictionary has none)."""
    if pe.index == 0:
        return
    access = "rw" if rx else "ro"
    o = objs.get(pe.index)
    if o is None:
        code = ObjectCode.VAR if pe.subindex == 0 else ObjectCode.RECORD
        o = OdObject(pe.index, pe.name or f"Object 0x{pe.index:04X}", code, {})
        if code != ObjectCode.VAR:
            o.entries[0] = Entry(0, "Number of entries", "UNSIGNED8", default=0)
        objs[pe.index] = o
    e = o.entries.get(pe.subindex)
    if e is None:
        e = Entry(pe.subindex, pe.name or f"SubIndex {pe.subindex:03d}", pe.type,
                  access=access, pdo=True, bits=pe.bits)  # fmt: skip
        o.entries[pe.subindex] = e
        if 0 in o.entries and pe.subindex > 0 and o.code != ObjectCode.VAR:
            e0 = o.entries[0]
            e0.default = e0.value = max(int(e0.value), pe.subindex)
    e.pdo = True
    if rx and e.access == "ro":
        e.access = "rw"
    if pe.bits != e.bits and pe.bits not in e.pdo_bits:
        e.pdo_bits = (*e.pdo_bits, pe.bits)


def _pdo_specs(dev: ET.Element, tag: str, pdos: tuple[PdoDescription, ...]) -> list[PdoSpec]:
    out = []
    for el, p in zip(dev.findall(tag), pdos, strict=True):
        excl = frozenset(num(x.text) for x in el.findall("Exclude") if x.text)
        assigned = el.get("Sm") is not None
        out.append(
            PdoSpec(
                dataclasses.replace(p, sm=p.sm if assigned else NO_SM),
                assigned,
                fixed=_true(el.get("Fixed")),
                mandatory=_true(el.get("Mandatory")),
                exclude=excl,
            )
        )
    return out


def _true(v: str | None) -> bool:
    return (v or "").strip().lower() in ("true", "1")


def from_esi(
    path: Path,
    product: int | None = None,
    revision: int | None = None,
    device_type: str | None = None,
    hint: str = "pick one with device_type: NAME (or product:/revision:)",
) -> GenericModel:
    """The model of one device of an ESI file. Ref: ETG.2000 §5."""
    desc, dev = read_esi_device(path, product, revision, device_type, hint=hint)
    warn: set[str] = set()
    try:
        rx = _pdo_specs(dev, "RxPdo", desc.rxpdos)
        tx = _pdo_specs(dev, "TxPdo", desc.txpdos)
    except ValueError as exc:
        raise EsiError(f"{path}: <Exclude> is not a PDO index ({exc})") from exc
    for s in (*rx, *tx):
        if len(s.pdo.entries) > 255:  # the SII's PDO category counts entries in one byte
            raise EsiError(
                f"{path}: PDO 0x{s.pdo.index:04X}: {len(s.pdo.entries)} entries, at most 255"
            )
        if desc.mailbox.protocols and s.assigned and s.pdo.sm not in (2, 3):
            warn.add(f"PDO 0x{s.pdo.index:04X} on SM{s.pdo.sm} (process data is SM2/SM3)")
    for tag in UNMODELLED:
        if dev.find(tag) is not None:
            warn.add(f"<{tag}>")
    dic = dev.find("Profile/Dictionary")
    where = f"{path.name} <Device {desc.order_code}>"
    dictionary: Callable[[set[str]], list[OdObject]] | None = None
    if dic is not None:
        d = dic

        def dictionary(w: set[str]) -> list[OdObject]:
            return read_objects(d, where, w)

        dictionary(warn)  # once now: the warnings, and a broken Dictionary fails early
    esc = desc.esc
    mailbox = bool(desc.mailbox.protocols)
    if mailbox and esc.pdi_control & DEVICE_EMULATION:
        # the ESC would answer AL control itself and no firmware would copy process data
        warn.add("ConfigData device emulation (0x0141 bit 0): off, the emulated firmware runs")
        esc = dataclasses.replace(esc, pdi_control=esc.pdi_control & ~DEVICE_EMULATION)
    elif not mailbox and not esc.pdi_control & DEVICE_EMULATION:
        # IO without a microcontroller: the ESC answers AL control (ecatsim/generic/pinio.py)
        warn.add("ConfigData device emulation (0x0141 bit 0): on, no mailbox and no firmware")
        esc = dataclasses.replace(esc, pdi_control=esc.pdi_control | DEVICE_EMULATION)
    if not mailbox:
        for kind in ("pd_out", "pd_in"):
            if sum(1 for sm in desc.sync_managers if sm.type == kind) > 1:
                warn.add(f"process data on several {kind} SMs (the first one carries it all)")
    desc = dataclasses.replace(
        desc,
        esc=esc,
        rxpdos=tuple(s.pdo for s in rx),
        txpdos=tuple(s.pdo for s in tx),
    )
    coe = dev.find("Mailbox/CoE")
    pdo_assign = coe is not None and _true(coe.get("PdoAssign"))
    choice = any(not s.assigned or not s.mandatory for s in (*rx, *tx))
    return GenericModel(
        desc=desc,
        rx=tuple(rx),
        tx=tuple(tx),
        dictionary=dictionary,
        warnings=sorted(warn),
        assign_writable=pdo_assign or choice,
        source=where,
    )


def pdo_entry(index: int, sub: int, bits: int, dtype: str, name: str) -> PdoEntry:
    """A PDO entry with an ESI/ENI data type name (any name: unknown ones go by bits)."""
    return PdoEntry(index, sub, bits, pdo_entry_type(dtype, bits), name)
