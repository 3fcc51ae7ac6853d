"""ETG.2000 ESI XML: export our device, and read any ESI into a device description (for
``ecatsim eeprom build``). The SII image is always built by ``sii.image.build_image``.

Ref: ETG.2000 (EtherCAT Slave Information) §5 (Device element: Type, Name, GroupType,
Profile/Dictionary, Fmmu, Sm, RxPdo/TxPdo, Mailbox, Dc, Eeprom).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from ecatsim.device.description import (
    COE_DETAILS,
    DATA_TYPES,
    DcOpMode,
    DeviceDescription,
    EscConfig,
    Identity,
    MailboxArea,
    MailboxConfig,
    PdoDescription,
    PdoEntry,
    SmConfig,
)
from ecatsim.generic.types import pdo_entry_type
from ecatsim.slave.od import ObjectDictionary

#: ETG.2000 data type names for our type names. Ref: ETG.2000 Table "base data types".
ESI_TYPES = {
    "BOOLEAN": "BOOL",
    "INTEGER8": "SINT",
    "INTEGER16": "INT",
    "INTEGER32": "DINT",
    "INTEGER64": "LINT",
    "UNSIGNED8": "USINT",
    "UNSIGNED16": "UINT",
    "UNSIGNED32": "UDINT",
    "UNSIGNED64": "ULINT",
    "REAL32": "REAL",
    "REAL64": "LREAL",
    "VISIBLE_STRING": "STRING",
    "OCTET_STRING": "OCTET_STRING",
}
FROM_ESI = {v: k for k, v in ESI_TYPES.items()}
SM_NAMES = {"mbx_out": "MBoxOut", "mbx_in": "MBoxIn", "pd_out": "Outputs", "pd_in": "Inputs"}
SM_FROM = {v: k for k, v in SM_NAMES.items()}
FMMU_NAMES = {"outputs": "Outputs", "inputs": "Inputs", "mbx_state": "MBoxState"}
FMMU_FROM = {v: k for k, v in FMMU_NAMES.items()}
COE_ATTRS = {
    "sdo_info": "SdoInfo",
    "pdo_assign": "PdoAssign",
    "pdo_config": "PdoConfig",
    "upload_at_startup": "PdoUpload",
    "complete_access": "CompleteAccess",
}


class EsiError(ValueError):
    """A bad ESI: one line naming the element and the problem."""


def _hex(v: int, width: int = 4) -> str:
    return f"#x{v:0{width}X}"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrs: str) -> ET.Element:
    e = ET.SubElement(parent, tag, attrs)
    if text is not None:
        e.text = text
    return e


def _pdo(parent: ET.Element, tag: str, pdo: PdoDescription) -> None:
    p = _sub(parent, tag, Fixed="false", Mandatory="true", Sm=str(pdo.sm))
    _sub(p, "Index", _hex(pdo.index))
    _sub(p, "Name", pdo.name)
    for e in pdo.entries:
        en = _sub(p, "Entry")
        _sub(en, "Index", _hex(e.index))
        _sub(en, "SubIndex", str(e.subindex))
        _sub(en, "BitLen", str(e.bits))
        _sub(en, "Name", e.name)
        _sub(en, "DataType", ESI_TYPES.get(e.type, e.type))


def _dictionary(profile: ET.Element, od: ObjectDictionary) -> None:
    dic = _sub(profile, "Dictionary")
    dts = _sub(dic, "DataTypes")
    seen: set[str] = set()
    objs = _sub(dic, "Objects")
    for o in od.objects.values():
        ob = _sub(objs, "Object")
        _sub(ob, "Index", _hex(o.index))
        _sub(ob, "Name", o.name)
        if o.code.name == "VAR":
            e = o.entries[0]
            tname = ESI_TYPES.get(e.dtype, e.dtype)
            if e.is_string:
                tname = f"STRING({max(1, e.size)})"
            _sub(ob, "Type", tname)
            _sub(ob, "BitSize", str(e.bits if not e.is_string else 8 * max(1, e.size)))
            seen.add(tname)
        else:
            tname = f"DT{o.index:04X}"
            _sub(ob, "Type", tname)
            dt = _sub(dts, "DataType")
            _sub(dt, "Name", tname)
            bit = 0
            for s, e in sorted(o.entries.items()):
                si = _sub(dt, "SubItem")
                _sub(si, "SubIdx", str(s))
                _sub(si, "Name", e.name)
                _sub(si, "Type", ESI_TYPES.get(e.dtype, e.dtype))
                size = 16 if s == 0 else e.bits
                _sub(si, "BitSize", str(size))
                _sub(si, "BitOffs", str(bit))
                bit += size
                _flags(si, e.access, e.pdo)
                seen.add(ESI_TYPES.get(e.dtype, e.dtype))
            _sub(dt, "BitSize", str(bit))
            _sub(ob, "BitSize", str(bit))
        if o.code.name == "VAR":
            _flags(ob, o.entries[0].access, o.entries[0].pdo)
    for t in sorted(seen):
        dt = ET.Element("DataType")
        _sub(dt, "Name", t)
        if t.startswith("STRING("):
            bits = 8 * int(t[7:-1])
        else:
            base = FROM_ESI.get(t)
            bits = DATA_TYPES[base][1] if base else 0
        _sub(dt, "BitSize", str(bits))
        dts.insert(0, dt)


def _flags(parent: ET.Element, access: str, pdo: bool) -> None:
    f = _sub(parent, "Flags")
    _sub(f, "Access", {"ro": "ro", "rw": "rw", "wo": "wo"}[access])
    if pdo:
        _sub(f, "PdoMapping", "R" if access == "rw" else "T")


def export_esi(desc: DeviceDescription, od: ObjectDictionary | None) -> bytes:
    """Our device as ETG.2000 ESI XML (UTF-8). Ref: ETG.2000 §5."""
    root = ET.Element("EtherCATInfo", Version="1.6")
    v = _sub(root, "Vendor")
    _sub(v, "Id", _hex(desc.identity.vendor_id))
    _sub(v, "Name", "TRINAMIC Motion Control GmbH & Co. KG")
    ds = _sub(root, "Descriptions")
    g = _sub(_sub(ds, "Groups"), "Group")
    _sub(g, "Type", desc.group)
    _sub(g, "Name", desc.group_name)
    dev = _sub(_sub(ds, "Devices"), "Device", Physics="YY")
    _sub(dev, "Type", desc.order_code, ProductCode=_hex(desc.identity.product_code, 8),
         RevisionNo=_hex(desc.identity.revision, 8))  # fmt: skip
    _sub(dev, "Name", desc.name)
    _sub(dev, "GroupType", desc.group)
    if od is not None:
        prof = _sub(dev, "Profile")
        _sub(prof, "ProfileNo", "402")
        _dictionary(prof, od)
    for f in desc.fmmus:
        _sub(dev, "Fmmu", FMMU_NAMES.get(f, f))
    for s in desc.sync_managers:
        attrs = {
            "DefaultSize": str(s.length),
            "StartAddress": _hex(s.start),
            "ControlByte": _hex(s.control, 2),
            "Enable": str(s.enable),
        }
        _sub(dev, "Sm", SM_NAMES.get(s.type, s.type), **attrs)
    for p in desc.rxpdos:
        _pdo(dev, "RxPdo", p)
    for p in desc.txpdos:
        _pdo(dev, "TxPdo", p)
    mb = desc.mailbox
    if mb.protocols:
        mbx = _sub(dev, "Mailbox", DataLinkLayer="true")
        if "eoe" in mb.protocols:  # the schema's order: AoE, EoE, CoE, FoE (ETG.2000)
            _sub(mbx, "EoE", IP="true", MAC="true")
        if "coe" in mb.protocols:
            attrs = {a: "true" for k, a in COE_ATTRS.items() if k in mb.coe_details}
            _sub(mbx, "CoE", **attrs)
        if "foe" in mb.protocols or mb.foe:
            _sub(mbx, "FoE")
    if desc.dc:
        dc = _sub(dev, "Dc")
        for m in desc.dc:
            om = _sub(dc, "OpMode")
            _sub(om, "Name", m.name)
            _sub(om, "Desc", m.description)
            _sub(om, "AssignActivate", _hex(m.assign_activate))
            _sub(om, "CycleTimeSync0", str(m.sync0_cycle), Factor="1")
            _sub(om, "ShiftTimeSync0", str(m.sync0_shift))
            _sub(om, "CycleTimeSync1", str(m.sync1_cycle), Factor="0")
            _sub(om, "ShiftTimeSync1", str(m.sync1_shift))
    e = desc.esc
    ee = _sub(dev, "Eeprom")
    _sub(ee, "ByteSize", str(e.eeprom_size_kbit * 128))
    cfg = b"".join(
        w.to_bytes(2, "little")
        for w in (e.pdi_control, e.pdi_config, e.sync_impulse_length, e.pdi_config2, e.alias)
    )
    _sub(ee, "ConfigData", cfg.hex().upper())
    b = mb.bootstrap_rx, mb.bootstrap_tx
    boot = b"".join(x.to_bytes(2, "little") for a in b for x in (a.offset, a.size))
    _sub(ee, "BootStrap", boot.hex().upper())
    if desc.mfcio_config:
        _mfcio_category(ee, desc.mfcio_config)
    ET.indent(root)
    body: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=False)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + body


def _mfcio_category(ee: ET.Element, data: bytes) -> None:
    """The TMC8460 MFCIO configuration as the printed examples write it, one comment per
    register saying what its byte means. Ref: TMC8460 §6.5.1 (Eeprom/Category CatNo 1)."""
    from ecatsim.mfcio.config import describe

    cat = _sub(ee, "Category")
    cat.append(ET.Comment(" TMC8460 MFCIO register configuration (loaded into 0x0580) "))
    for line in describe(data):
        cat.append(ET.Comment(f" {line.strip()} "))
    _sub(cat, "CatNo", "1")
    _sub(cat, "Data", data.hex().upper())


# ------------------------------------------------------------------------ reading


def _num(text: str | None, where: str) -> int:
    if text is None:
        raise EsiError(f"{where}: missing value")
    t = text.strip()
    try:
        if t.startswith("#x"):
            return int(t[2:], 16)
        return int(t, 0)
    except ValueError as exc:
        raise EsiError(f"{where}: {t!r} is not a number") from exc


def _text(el: ET.Element, tag: str, where: str, default: str | None = None) -> str:
    c = el.find(tag)
    if c is None or c.text is None:
        if default is None:
            raise EsiError(f"{where}: missing <{tag}>")
        return default
    return c.text.strip()


def _read_pdos(dev: ET.Element, tag: str) -> tuple[PdoDescription, ...]:
    out = []
    for i, p in enumerate(dev.findall(tag)):
        where = f"<{tag}> #{i + 1}"
        entries = []
        for j, e in enumerate(p.findall("Entry")):
            ew = f"{where} <Entry> #{j + 1}"
            dt = _text(e, "DataType", ew, "")
            bits = _num(_text(e, "BitLen", ew), f"{ew} <BitLen>")
            entries.append(
                PdoEntry(
                    _num(_text(e, "Index", ew), f"{ew} <Index>"),
                    _num(_text(e, "SubIndex", ew, "0"), f"{ew} <SubIndex>"),
                    bits,
                    FROM_ESI[dt] if dt in FROM_ESI else pdo_entry_type(dt, bits),
                    _text(e, "Name", ew, ""),
                )
            )
        out.append(
            PdoDescription(
                _num(_text(p, "Index", where), f"{where} <Index>"),
                _text(p, "Name", where, ""),
                _num(p.get("Sm", "2" if tag == "RxPdo" else "3"), f"{where} Sm"),
                tuple(entries),
            )
        )
    return tuple(out)


def read_esi(
    path: Path, product: int | None = None, revision: int | None = None
) -> DeviceDescription:
    """The device of an ESI file as a description (for building its SII image).

    Several devices: pick by ``product`` and ``revision``. Ref: ETG.2000 §5.
    """
    return read_esi_device(path, product, revision)[0]


def parse_root(path: Path) -> ET.Element:
    """The <EtherCATInfo> root of an ESI file; one-line EsiError otherwise."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise EsiError(f"{path}: not a readable XML file ({exc})") from exc
    if root.tag != "EtherCATInfo":
        raise EsiError(f"{path}: root element is <{root.tag}>, expected <EtherCATInfo>")
    return root


def device_ids(root: ET.Element, path: Path) -> list[tuple[ET.Element, str, int, int]]:
    """Every <Device> of an ESI with its <Type> text, ProductCode and RevisionNo."""
    devices = root.findall("Descriptions/Devices/Device")
    if not devices:
        raise EsiError(f"{path}: no <Device> in <Descriptions><Devices>")
    out = []
    for d in devices:
        t = d.find("Type")
        if t is None:
            raise EsiError(f"{path}: <Device> without <Type>")
        pc = _num(t.get("ProductCode"), f"{path}: <Type ProductCode>")
        rv = _num(t.get("RevisionNo", "0"), f"{path}: <Type RevisionNo>")
        out.append((d, (t.text or "").strip(), pc, rv))
    return out


def read_esi_device(
    path: Path,
    product: int | None = None,
    revision: int | None = None,
    device_type: str | None = None,
    *,
    hint: str = "pick one with --product/--revision",
) -> tuple[DeviceDescription, ET.Element]:
    """The description of one device of an ESI and its <Device> element.

    Chosen by ``device_type`` (the <Type> text), ``product`` and ``revision``; several
    matches are refused with their list. Ref: ETG.2000 §5 (Device/Type).
    """
    root = parse_root(path)
    vendor = _num(_text(root, "Vendor/Id", f"{path}"), f"{path}: <Vendor><Id>")
    chosen = []
    found = []
    for d, tname, pc, rv in device_ids(root, path):
        found.append(f"--product {pc:#x} --revision {rv:#x}")
        if (
            (product is None or pc == product)
            and (revision is None or rv == revision)
            and (device_type is None or tname == device_type)
        ):
            t = d.find("Type")
            assert t is not None
            chosen.append((d, t, pc, rv))
    if not chosen:
        want = " ".join(
            f"--{k} {v} ({v:#x})" if isinstance(v, int) else f"device_type {v}"
            for k, v in (("type", device_type), ("product", product), ("revision", revision))
            if v is not None
        )
        raise EsiError(f"{path}: no device matches {want}; it has: {'; '.join(found)}")
    if len(chosen) > 1:
        ids = ", ".join(f"{(t.text or '').strip()} {pc:#x}/{rv:#x}" for _d, t, pc, rv in chosen)
        raise EsiError(f"{path}: {len(chosen)} devices ({ids}): {hint}")
    dev, typ, pc, rv = chosen[0]
    where = f"{path}: <Device {typ.text}>"
    sms = []
    mbx_out = mbx_in = MailboxArea(0, 0)
    for i, s in enumerate(dev.findall("Sm")):
        kind = SM_FROM.get((s.text or "").strip(), "unused")
        sw = f"{where} <Sm> #{i + 1}"
        sm = SmConfig(
            _num(s.get("StartAddress", "0"), f"{sw} StartAddress"),
            _num(s.get("DefaultSize", "0"), f"{sw} DefaultSize"),
            _num(s.get("ControlByte", "0"), f"{sw} ControlByte"),
            _num(s.get("Enable", "1"), f"{sw} Enable"),
            kind,
        )
        sms.append(sm)
        if kind == "mbx_out":
            mbx_out = MailboxArea(sm.start, sm.length)
        elif kind == "mbx_in":
            mbx_in = MailboxArea(sm.start, sm.length)
    protocols: list[str] = []
    details: list[str] = []
    mb = dev.find("Mailbox")
    if mb is not None:
        coe = mb.find("CoE")
        if coe is not None:
            protocols.append("coe")
            details.append("sdo")
            for k, a in COE_ATTRS.items():
                if coe.get(a, "false").lower() in ("true", "1"):
                    details.append(k)
        if mb.find("FoE") is not None:
            protocols.append("foe")
        for tag, name in (("EoE", "eoe"), ("SoE", "soe"), ("AoE", "aoe"), ("VoE", "voe")):
            if mb.find(tag) is not None:
                protocols.append(name)
    ee = dev.find("Eeprom")
    mfcio = b""
    cfg = bytes(14)
    size = 4096
    boot = bytes(8)
    if ee is not None:
        try:
            cfg = bytes.fromhex(_text(ee, "ConfigData", where, "")).ljust(14, b"\x00")
            boot = bytes.fromhex(_text(ee, "BootStrap", where, "")).ljust(8, b"\x00")
        except ValueError as exc:
            raise EsiError(f"{where} <Eeprom>: ConfigData/BootStrap is not hex") from exc
        size = _num(_text(ee, "ByteSize", where, "4096"), f"{where} <ByteSize>")
        for cat in ee.findall("Category"):
            if _num(_text(cat, "CatNo", where), f"{where} <Category><CatNo>") != 1:
                continue
            try:
                mfcio = bytes.fromhex(_text(cat, "Data", where, ""))
            except ValueError as exc:
                raise EsiError(f"{where} <Category> 1: Data is not hex") from exc
            if len(mfcio) % 2:
                mfcio += b"\x00"
    w = [int.from_bytes(cfg[i : i + 2], "little") for i in range(0, 14, 2)]
    bw = [int.from_bytes(boot[i : i + 2], "little") for i in range(0, 8, 2)]
    dcs = []
    for i, om in enumerate(dev.findall("Dc/OpMode")):
        ow = f"{where} <OpMode> #{i + 1}"
        dcs.append(
            DcOpMode(
                _text(om, "Name", ow),
                _text(om, "Desc", ow, ""),
                _num(_text(om, "AssignActivate", ow, "0"), f"{ow} <AssignActivate>"),
                _num(_text(om, "CycleTimeSync0", ow, "0"), f"{ow} <CycleTimeSync0>"),
                _num(_text(om, "ShiftTimeSync0", ow, "0"), f"{ow} <ShiftTimeSync0>"),
                _num(_text(om, "CycleTimeSync1", ow, "0"), f"{ow} <CycleTimeSync1>"),
                _num(_text(om, "ShiftTimeSync1", ow, "0"), f"{ow} <ShiftTimeSync1>"),
            )
        )
    desc = DeviceDescription(
        source=str(path),
        name=_text(dev, "Name", where),
        order_code=(typ.text or "").strip(),
        group=_text(dev, "GroupType", where, ""),
        group_name="",
        hardware_version="",
        software_version="",
        identity=Identity(vendor, pc, rv, 0),
        esc=EscConfig(w[0], w[1], w[2], w[3], w[4], max(1, size // 128)),
        mailbox=MailboxConfig(
            mbx_out,
            mbx_in,
            MailboxArea(bw[0], bw[1]),
            MailboxArea(bw[2], bw[3]),
            tuple(protocols),
            tuple(d for d in COE_DETAILS if d in details),
            "foe" in protocols,
        ),
        sync_managers=tuple(sms),
        fmmus=tuple(FMMU_FROM.get((f.text or "").strip(), "unused") for f in dev.findall("Fmmu")),
        rxpdos=_read_pdos(dev, "RxPdo"),
        txpdos=_read_pdos(dev, "TxPdo"),
        dc=tuple(dcs),
        mfcio_config=mfcio,
    )
    return desc, dev
