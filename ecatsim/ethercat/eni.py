"""An ENI (EtherCAT Network Information, ETG.2100) as a segment: one slave per
<Config><Slave>, in order, identity from <Info>. Each slave's model, in this order:

1. built-in, where the identity is one of ours (TMC8670 drive, TMC8460 MFCIO slave);
2. an ESI from ``esi_dir`` whose device has the same vendor, product and revision;
3. made from the ENI itself: <ProcessData> PDOs and entries, <Mailbox> SM areas and
   protocols, the PDOs its CoE InitCmds write into 0x1C12/0x1C13 and the entries they
   write into 0x16xx/0x1Axx. A PDO named but described nowhere exists with no entries
   (one warning naming the slave and the PDO); an object an InitCmd writes that nothing
   describes is made to take that write.

Ref: ETG.2100 (ENI: Config/Slave/Info, ProcessData, Mailbox, CoE InitCmds); ETG.2000 §5.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import structlog

from ecatsim.device.description import (
    DeviceDescription,
    EscConfig,
    Identity,
    MailboxArea,
    MailboxConfig,
    PdoDescription,
    SmConfig,
)
from ecatsim.device.esi import EsiError, device_ids, parse_root
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import SlaveConfig
from ecatsim.generic.dictionary import num
from ecatsim.generic.model import GenericModel, PdoSpec, pdo_entry
from ecatsim.generic.types import by_bits
from ecatsim.slave.od import Entry, ObjectCode, OdObject

log = structlog.get_logger("ecatsim.ethercat.eni")

#: identities with a built-in model: (vendor, product) -> device type
BUILT_IN = {(0x286, 8670): "tmc8670", (0x286, 8460): "tmc8460"}
RX_ASSIGN, TX_ASSIGN = 0x1C12, 0x1C13
#: the ESC configuration a made-up slave's SII carries: SPI PDI, firmware behind it
#: (device emulation off), as the TMC8670's (TMC8460 §5.26, §6.2)
ESC = EscConfig(0x0C05, 0x0E03, 100, 0, 0, 32)
PROTOCOLS = {"AoE": "aoe", "EoE": "eoe", "CoE": "coe", "FoE": "foe", "SoE": "soe", "VoE": "voe"}
COE_DETAILS = ("sdo", "sdo_info", "pdo_assign", "pdo_config", "complete_access")


@dataclass
class EniSlave:
    """One <Config><Slave>: its identity, the model it gets and its slave entry."""

    position: int
    name: str
    identity: Identity
    model: str
    config: SlaveConfig
    warnings: list[str] = field(default_factory=list)


def _n(el: ET.Element | None, tag: str, where: str, default: int | None = None) -> int:
    t = el.findtext(tag) if el is not None else None
    if t is None or not t.strip():
        if default is None:
            raise UserError(f"{where}: missing <{tag}>")
        return default
    try:
        return num(t)
    except ValueError:
        raise UserError(f"{where}: <{tag}> {t.strip()!r} is not a number") from None


@dataclass
class _CoeWrite:
    index: int
    sub: int
    data: bytes
    complete: bool


def _coe_writes(slave: ET.Element, where: str) -> list[_CoeWrite]:
    """The SDO downloads of the slave's CoE InitCmds, in order."""
    out = []
    for i, c in enumerate(slave.findall("Mailbox/CoE/InitCmds/InitCmd")):
        w = f"{where} CoE InitCmd #{i + 1}"
        if _n(c, "Ccs", w, 1) != 1:
            continue  # an upload: nothing to make
        try:
            data = bytes.fromhex((c.findtext("Data") or "").strip())
        except ValueError:
            raise UserError(f"{w}: <Data> is not hex") from None
        ca = (c.get("CompleteAccess") or c.findtext("CompleteAccess") or "").lower()
        out.append(_CoeWrite(_n(c, "Index", w), _n(c, "SubIndex", w, 0), data, ca in ("true", "1")))
    return out


def _final_lists(writes: list[_CoeWrite]) -> dict[int, list[int]]:
    """Each 0x1C12/0x1C13/0x16xx/0x1Axx object's value list after the writes (subindex 0 =
    count, 1.. = values), replayed as the slave takes them."""
    objs: dict[int, dict[int, int]] = {}
    for w in writes:
        if not (0x1600 <= w.index < 0x1C00 or w.index in (RX_ASSIGN, TX_ASSIGN)):
            continue
        size = 2 if w.index in (RX_ASSIGN, TX_ASSIGN) else 4
        o = objs.setdefault(w.index, {0: 0})
        if w.complete:
            p = 0
            if w.sub == 0 and len(w.data) >= 2:  # subindex 0 as 16 bits
                o[0] = w.data[0]
                p = 2
            s = max(w.sub, 1)
            while p + size <= len(w.data):
                o[s] = int.from_bytes(w.data[p : p + size], "little")
                p += size
                s += 1
        elif w.data:
            o[w.sub] = int.from_bytes(w.data[:size], "little")
    return {i: [o.get(s, 0) for s in range(1, o.get(0, 0) + 1)] for i, o in objs.items()}


def _pdos(pd: ET.Element | None, tag: str, where: str) -> dict[int, PdoDescription]:
    out: dict[int, PdoDescription] = {}
    for i, p in enumerate(pd.findall(tag) if pd is not None else []):
        w = f"{where} <{tag}> #{i + 1}"
        entries = tuple(
            pdo_entry(
                _n(e, "Index", w),
                _n(e, "SubIndex", w, 0),
                _n(e, "BitLen", w),
                e.findtext("DataType") or "",
                (e.findtext("Name") or "").strip(),
            )
            for e in p.findall("Entry")
        )
        sm = 2 if tag == "RxPdo" else 3
        out[_n(p, "Index", w)] = PdoDescription(
            _n(p, "Index", w), (p.findtext("Name") or "").strip(), sm, entries
        )
    return out


def _extra_objects(writes: list[_CoeWrite], known: set[int]) -> list[OdObject]:
    """Objects the InitCmds write that nothing describes: made to take those writes (a
    value of the written size; complete access: a record of equal entries)."""
    made: dict[int, OdObject] = {}
    for w in writes:
        if w.index in known or 0x1600 <= w.index < 0x1C00 or w.index in (RX_ASSIGN, TX_ASSIGN):
            continue
        o = made.get(w.index)
        if w.complete and len(w.data) >= 2:
            n = w.data[0] if w.sub == 0 else 1
            rest = len(w.data) - (2 if w.sub == 0 else 0)
            size = rest // n if n and rest % n == 0 and rest // n in (1, 2, 4, 8) else 0
            if not size:
                continue
            entries = {0: Entry(0, "Number of entries", "UNSIGNED8", access="rw", default=n)}
            for s in range(1, n + 1):
                entries[s] = Entry(s, f"SubIndex {s:03d}", by_bits(8 * size), access="rw")
            made[w.index] = OdObject(w.index, f"Object 0x{w.index:04X}", ObjectCode.RECORD, entries)
            continue
        bits = 8 * len(w.data) if len(w.data) in (1, 2, 4, 8) else 0
        dtype = by_bits(bits) if bits else "OCTET_STRING"
        e = Entry(w.sub, f"SubIndex {w.sub:03d}", dtype, access="rw", bits=bits or 8 * len(w.data))
        if o is None:
            code = ObjectCode.VAR if w.sub == 0 else ObjectCode.RECORD
            o = made[w.index] = OdObject(w.index, f"Object 0x{w.index:04X}", code, {})
            if code == ObjectCode.RECORD:
                o.entries[0] = Entry(0, "Number of entries", "UNSIGNED8", default=0)
        if w.sub not in o.entries:
            o.entries[w.sub] = e
            if w.sub and o.code == ObjectCode.RECORD:
                o.entries[0].value = o.entries[0].default = max(int(o.entries[0].value), w.sub)
    return list(made.values())


def _sm(pd: ET.Element | None, n: int, start: int, ctrl: int, size: int, kind: str) -> SmConfig:
    el = pd.find(f"Sm{n}") if pd is not None else None
    if el is not None:
        start = num(el.findtext("StartAddress") or str(start))
        ctrl = num(el.findtext("ControlByte") or str(ctrl))
    return SmConfig(start, size, ctrl, 1, kind)


def synthesize(slave: ET.Element, identity: Identity, name: str, where: str) -> GenericModel:
    """A model from the ENI alone."""
    warn: list[str] = []
    pd = slave.find("ProcessData")
    writes = _coe_writes(slave, where)
    lists = _final_lists(writes)
    described = {**_pdos(pd, "RxPdo", where), **_pdos(pd, "TxPdo", where)}
    mbx = slave.find("Mailbox")
    protocols: tuple[str, ...] = ()
    rx_area = tx_area = MailboxArea(0, 0)
    if mbx is not None:
        rx_area = MailboxArea(
            _n(mbx, "Send/Start", where, 0x1000), _n(mbx, "Send/Length", where, 128)
        )
        tx_area = MailboxArea(
            _n(mbx, "Recv/Start", where, 0x1080), _n(mbx, "Recv/Length", where, 128)
        )
        protocols = tuple(
            PROTOCOLS[p.text.strip()]
            for p in mbx.findall("Protocol")
            if p.text and p.text.strip() in PROTOCOLS
        )
        if not protocols and mbx.find("CoE") is not None:
            protocols = ("coe",)
    specs: dict[int, list[PdoSpec]] = {RX_ASSIGN: [], TX_ASSIGN: []}
    for assign, lo in ((RX_ASSIGN, 0x1600), (TX_ASSIGN, 0x1A00)):
        sm_el = pd.find(f"Sm{assign - 0x1C10}") if pd is not None else None
        sm_pdos = [num(p.text) for p in sm_el.findall("Pdo") if p.text] if sm_el is not None else []
        assigned = lists.get(assign, sm_pdos)
        indices = [i for i in described if lo <= i < lo + 0x400]
        indices += [i for i in assigned if i not in indices]
        for index in indices:
            p = described.get(index)
            if p is None and index in lists:
                entries = tuple(
                    pdo_entry(v >> 16, (v >> 8) & 0xFF, v & 0xFF, "", "") for v in lists[index]
                )
                p = PdoDescription(index, f"PDO 0x{index:04X}", assign - 0x1C10, entries)
            if p is None:
                warn.append(f"{where} ({name}): PDO 0x{index:04X} is described nowhere: no entries")
                p = PdoDescription(index, f"PDO 0x{index:04X}", assign - 0x1C10, ())
            on = index in assigned
            p = PdoDescription(p.index, p.name, p.sm if on else 0xFF, p.entries)
            specs[assign].append(PdoSpec(p, on))
    rx_bits = sum(s.pdo.bits for s in specs[RX_ASSIGN] if s.assigned)
    tx_bits = sum(s.pdo.bits for s in specs[TX_ASSIGN] if s.assigned)
    mb_end = max(rx_area.offset + rx_area.size, tx_area.offset + tx_area.size, 0x1000)
    pd_out = (mb_end + 0xFF) & ~0xFF
    unused = SmConfig(0, 0, 0, 0, "unused")
    sms = [
        SmConfig(rx_area.offset, rx_area.size, 0x26, 1, "mbx_out") if mbx is not None else unused,
        SmConfig(tx_area.offset, tx_area.size, 0x22, 1, "mbx_in") if mbx is not None else unused,
        _sm(pd, 2, pd_out, 0x64, (rx_bits + 7) // 8, "pd_out"),
        _sm(pd, 3, pd_out + 0x100, 0x20, (tx_bits + 7) // 8, "pd_in"),
    ]
    desc = DeviceDescription(
        source=where,
        name=name,
        order_code=name,
        group="",
        group_name="",
        hardware_version="",
        software_version="",
        identity=identity,
        esc=ESC
        if mbx is not None
        else dataclasses.replace(ESC, pdi_control=ESC.pdi_control | 0x0100),
        mailbox=MailboxConfig(
            rx_area,
            tx_area,
            MailboxArea(0, 0),
            MailboxArea(0, 0),
            protocols,
            COE_DETAILS if "coe" in protocols else (),
            "foe" in protocols,
        ),
        sync_managers=tuple(sms),
        fmmus=("outputs", "inputs", "mbx_state") if mbx is not None else ("outputs", "inputs"),
        rxpdos=tuple(s.pdo for s in specs[RX_ASSIGN]),
        txpdos=tuple(s.pdo for s in specs[TX_ASSIGN]),
        dc=(),
    )
    known = {e.index for s in (*specs[RX_ASSIGN], *specs[TX_ASSIGN]) for e in s.pdo.entries}

    def dictionary(_w: set[str]) -> list[OdObject]:
        return _extra_objects(writes, known)

    return GenericModel(
        desc=desc,
        rx=tuple(specs[RX_ASSIGN]),
        tx=tuple(specs[TX_ASSIGN]),
        dictionary=dictionary,
        warnings=warn,
        assign_writable=True,
        source=where,
    )


def _esi_for(esi_dir: Path | None, idn: Identity) -> tuple[Path, str] | None:
    """The first ESI in ``esi_dir`` with a device of this identity: (file, <Type> text)."""
    if esi_dir is None:
        return None
    for f in sorted(esi_dir.glob("*.xml")):
        try:
            root = parse_root(f)
            vendor = num(root.findtext("Vendor/Id"))
            for _d, tname, pc, rv in device_ids(root, f):
                if (vendor, pc, rv) == (idn.vendor_id, idn.product_code, idn.revision):
                    return f, tname
        except (EsiError, ValueError):
            continue  # a broken file here is another device's problem
    return None


def load_eni(path: Path, esi_dir: Path | None = None) -> list[EniSlave]:
    """The slaves of an ENI with the model each gets. Ref: ETG.2100 (Config/Slave)."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise UserError(f"{path}: not a readable ENI file ({exc})") from exc
    if root.tag != "EtherCATConfig":
        raise UserError(f"{path}: root element is <{root.tag}>, expected <EtherCATConfig>")
    if esi_dir is not None and not esi_dir.is_dir():
        raise UserError(f"--esi-dir {esi_dir}: not a directory")
    slaves = root.findall("Config/Slave")
    if not slaves:
        raise UserError(f"{path}: no <Slave> in <Config>")
    out = []
    for i, s in enumerate(slaves):
        where = f"{path.name}: <Slave> #{i + 1}"
        info = s.find("Info")
        name = (info.findtext("Name") if info is not None else None) or f"Slave {i + 1}"
        name = name.strip()
        idn = Identity(
            _n(info, "VendorId", where),
            _n(info, "ProductCode", where),
            _n(info, "RevisionNo", where, 0),
            _n(info, "SerialNo", where, 0),
        )
        serial = idn.serial or None
        builtin = BUILT_IN.get((idn.vendor_id, idn.product_code))
        esi = _esi_for(esi_dir, idn)
        if builtin is not None:
            cfg = SlaveConfig(device=builtin, serial=serial, name=name)
            out.append(EniSlave(i, name, idn, f"built-in {builtin}", cfg))
        elif esi is not None:
            f, tname = esi
            cfg = SlaveConfig(device="generic", esi=f, device_type=tname, product=idn.product_code,
                              revision=idn.revision, serial=serial, name=name)  # fmt: skip
            out.append(EniSlave(i, name, idn, f"ESI {f.name} ({tname})", cfg))
        else:
            model = synthesize(s, idn, name, where)
            cfg = SlaveConfig(device="generic", serial=serial, name=name, model=model)
            out.append(EniSlave(i, name, idn, "from the ENI", cfg, list(model.warnings)))
    return out


def eni_segment_slaves(path: Path, esi_dir: Path | None) -> tuple[SlaveConfig, ...]:
    """The slave entries of an ENI for a segment; each made-up PDO warned about once."""
    slaves = load_eni(path, esi_dir)
    for s in slaves:
        for w in s.warnings:
            log.warning("eni_pdo_undescribed", detail=w)
    return tuple(s.config for s in slaves)


def format_slaves(slaves: list[EniSlave]) -> str:
    """``ecatsim eni show``: one slave a line."""
    lines = []
    for s in slaves:
        i = s.identity
        lines.append(
            f"{s.position:3d}  {s.name}  vendor 0x{i.vendor_id:08X} product 0x{i.product_code:08X}"
            f" revision 0x{i.revision:08X}  -> {s.model}"
        )
        lines += [f"     warning: {w}" for w in s.warnings]
    return "\n".join(lines)
