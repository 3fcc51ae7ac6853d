"""The device description: one YAML source for the SII image, the ESI and the OD.

Every problem is one line naming the file, the key path and the fix.
Ref: ETG.2010 (SII content), ETG.2000 (ESI), TMC8670 datasheet (identity and PDOs).
"""

from __future__ import annotations

import importlib.resources
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import yaml

#: ETG.1000.6 Table 63 / CiA 301 basic data types: name -> (code, bits).
DATA_TYPES: dict[str, tuple[int, int]] = {
    "BOOLEAN": (0x0001, 1),
    "INTEGER8": (0x0002, 8),
    "INTEGER16": (0x0003, 16),
    "INTEGER32": (0x0004, 32),
    "UNSIGNED8": (0x0005, 8),
    "UNSIGNED16": (0x0006, 16),
    "UNSIGNED32": (0x0007, 32),
    "REAL32": (0x0008, 32),
    "VISIBLE_STRING": (0x0009, 0),
    "OCTET_STRING": (0x000A, 0),
    "UNICODE_STRING": (0x000B, 0),
    "INTEGER24": (0x0010, 24),
    "REAL64": (0x0011, 64),
    "INTEGER64": (0x0015, 64),
    "UNSIGNED24": (0x0016, 24),
    "UNSIGNED64": (0x001B, 64),
    # BIT1..BIT8 (ETG.1000.6 Table 63): bit strings of an ESI's PDO entries
    **{f"BIT{n}": (0x002F + n, n) for n in range(1, 9)},
}

MAILBOX_PROTOCOLS = {"aoe": 0x01, "eoe": 0x02, "coe": 0x04, "foe": 0x08, "soe": 0x10, "voe": 0x20}
COE_DETAILS = {
    "sdo": 0x01,
    "sdo_info": 0x02,
    "pdo_assign": 0x04,
    "pdo_config": 0x08,
    "upload_at_startup": 0x10,
    "complete_access": 0x20,
}
SM_TYPES = {"unused": 0, "mbx_out": 1, "mbx_in": 2, "pd_out": 3, "pd_in": 4}
FMMU_TYPES = {"unused": 0, "outputs": 1, "inputs": 2, "mbx_state": 3}


def _bits(names: tuple[str, ...], table: dict[str, int]) -> int:
    v = 0
    for n in names:
        v |= table[n]
    return v


class DescriptionError(ValueError):
    """A device description is malformed; the message is one line with file and key."""


@dataclass(frozen=True, slots=True)
class Identity:
    vendor_id: int
    product_code: int
    revision: int
    serial: int


@dataclass(frozen=True, slots=True)
class EscConfig:
    pdi_control: int
    pdi_config: int
    sync_impulse_length: int
    pdi_config2: int
    alias: int
    eeprom_size_kbit: int


@dataclass(frozen=True, slots=True)
class MailboxArea:
    offset: int
    size: int


@dataclass(frozen=True, slots=True)
class MailboxConfig:
    rx: MailboxArea
    tx: MailboxArea
    bootstrap_rx: MailboxArea
    bootstrap_tx: MailboxArea
    protocols: tuple[str, ...]
    coe_details: tuple[str, ...]
    foe: bool

    @property
    def protocol_bits(self) -> int:
        """SII word 0x1C. Ref: ETG.2010 Table 2."""
        return _bits(self.protocols, MAILBOX_PROTOCOLS)

    @property
    def coe_detail_bits(self) -> int:
        """General category CoE details byte. Ref: ETG.2010 Table 5."""
        return _bits(self.coe_details, COE_DETAILS)


@dataclass(frozen=True, slots=True)
class SmConfig:
    start: int
    length: int
    control: int
    enable: int
    type: str

    @property
    def type_code(self) -> int:
        return SM_TYPES[self.type]


@dataclass(frozen=True, slots=True)
class PdoEntry:
    index: int
    subindex: int
    bits: int
    type: str
    name: str

    @property
    def type_code(self) -> int:
        return DATA_TYPES[self.type][0] if self.type in DATA_TYPES else 0


@dataclass(frozen=True, slots=True)
class PdoDescription:
    index: int
    name: str
    sm: int
    entries: tuple[PdoEntry, ...]

    @property
    def bits(self) -> int:
        return sum(e.bits for e in self.entries)


@dataclass(frozen=True, slots=True)
class DcOpMode:
    name: str
    description: str
    assign_activate: int
    sync0_cycle: int
    sync0_shift: int
    sync1_cycle: int
    sync1_shift: int


@dataclass(frozen=True, slots=True)
class DeviceDescription:
    source: str
    name: str
    order_code: str
    group: str
    group_name: str
    hardware_version: str
    software_version: str
    identity: Identity
    esc: EscConfig
    mailbox: MailboxConfig
    sync_managers: tuple[SmConfig, ...]
    fmmus: tuple[str, ...]
    rxpdos: tuple[PdoDescription, ...]
    txpdos: tuple[PdoDescription, ...]
    dc: tuple[DcOpMode, ...]
    od_raw: Any = None
    motor_raw: Any = None
    #: the TMC8460 MFCIO configuration: the data of the SII category of type 1 that is
    #: written first, at word 0x40 (TMC8460 §6.3); empty: none
    mfcio_config: bytes = b""

    @property
    def rx_bytes(self) -> int:
        return (sum(p.bits for p in self.rxpdos) + 7) // 8

    @property
    def tx_bytes(self) -> int:
        return (sum(p.bits for p in self.txpdos) + 7) // 8


class _Reader:
    """Typed access to a YAML mapping with one-line errors naming file and key path."""

    def __init__(self, src: str) -> None:
        self.src = src

    def err(self, key: str, msg: str) -> DescriptionError:
        return DescriptionError(f"{self.src}: {key}: {msg}")

    def mapping(self, v: Any, key: str, allowed: set[str]) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise self.err(key, "expected a mapping")
        bad = set(v) - allowed
        if bad:
            k = sorted(bad)[0]
            raise self.err(
                f"{key}.{k}" if key else k, f"unknown key (allowed: {', '.join(sorted(allowed))})"
            )
        return v

    def int_(
        self, d: dict[str, Any], key: str, path: str, lo: int, hi: int, default: int | None = None
    ) -> int:
        if key not in d:
            if default is None:
                raise self.err(f"{path}.{key}" if path else key, "missing")
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.err(
                f"{path}.{key}" if path else key, f"expected an integer {lo}..{hi}, got {v!r}"
            )
        return v

    def str_(self, d: dict[str, Any], key: str, path: str, default: str | None = None) -> str:
        if key not in d:
            if default is None:
                raise self.err(f"{path}.{key}" if path else key, "missing")
            return default
        v = d[key]
        if not isinstance(v, str):
            raise self.err(f"{path}.{key}" if path else key, f"expected a string, got {v!r}")
        return v


def _area(r: _Reader, d: dict[str, Any], key: str) -> MailboxArea:
    if key not in d:
        return MailboxArea(0, 0)
    m = r.mapping(d[key], f"mailbox.{key}", {"offset", "size"})
    return MailboxArea(
        r.int_(m, "offset", f"mailbox.{key}", 0, 0xFFFF),
        r.int_(m, "size", f"mailbox.{key}", 0, 0xFFFF),
    )


def _pdos(r: _Reader, raw: Any, key: str) -> tuple[PdoDescription, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise r.err(key, "expected a list of PDOs")
    out = []
    for i, p in enumerate(raw):
        path = f"{key}[{i}]"
        p = r.mapping(p, path, {"index", "name", "sm", "entries"})
        entries = []
        for j, e in enumerate(p.get("entries") or []):
            ep = f"{path}.entries[{j}]"
            e = r.mapping(e, ep, {"index", "subindex", "bits", "type", "name"})
            typ = r.str_(e, "type", ep, "UNSIGNED8")
            if typ not in DATA_TYPES:
                raise r.err(
                    f"{ep}.type", f"unknown data type {typ!r} (use e.g. UNSIGNED16, INTEGER32)"
                )
            entries.append(
                PdoEntry(
                    r.int_(e, "index", ep, 0, 0xFFFF),
                    r.int_(e, "subindex", ep, 0, 0xFF, 0),
                    r.int_(e, "bits", ep, 1, 64),
                    typ,
                    r.str_(e, "name", ep, ""),
                )
            )
        out.append(
            PdoDescription(
                r.int_(p, "index", path, 0x1600, 0x1BFF),
                r.str_(p, "name", path, ""),
                r.int_(p, "sm", path, 0, 5),
                tuple(entries),
            )
        )
    return tuple(out)


_TOP = {
    "device",
    "identity",
    "esc",
    "mailbox",
    "sync_managers",
    "fmmus",
    "rxpdos",
    "txpdos",
    "dc",
    "od",
    "motor",
    "mfcio",
}


def _mfcio(r: _Reader, raw: Any) -> bytes:
    """``mfcio:`` -> the category-1 data: ``{config: HEX}`` as an ESI prints it, or
    ``{default: BYTE, registers: {NAME: BYTE}}`` (names of TMC8460 §6.2 Table 133)."""
    if raw is None:
        return b""
    from ecatsim.mfcio.config import category_body
    from ecatsim.mfcio.regs import BY_NAME, N_CONFIGURED

    d = r.mapping(raw, "mfcio", {"config", "default", "registers"})
    if "config" in d:
        text = d["config"]
        try:
            data = bytes.fromhex(str(text))
        except ValueError:
            raise r.err("mfcio.config", f"{text!r} is not hex bytes like 1E0000101E10") from None
        if len(data) > N_CONFIGURED:
            raise r.err("mfcio.config", f"{len(data)} bytes: at most {N_CONFIGURED}")
        return data + b"\x00" if len(data) % 2 else data
    vec = bytearray([r.int_(d, "default", "mfcio", 0, 0x1F, 0)] * N_CONFIGURED)
    regs = d.get("registers") or {}
    if not isinstance(regs, dict):
        raise r.err("mfcio.registers", "expected a mapping NAME: byte, e.g. {ENC_MODE: 0x1E}")
    for name in regs:
        reg = BY_NAME.get(str(name))
        if reg is None or reg.num >= N_CONFIGURED:
            raise r.err(f"mfcio.registers.{name}", "unknown MFCIO register (TMC8460 Table 133)")
        vec[reg.num] = r.int_(regs, name, "mfcio.registers", 0, 0x1F)
    return category_body(bytes(vec))


def parse_description(data: Any, src: str) -> DeviceDescription:
    """Validate a loaded YAML document."""
    r = _Reader(src)
    if not isinstance(data, dict):
        what = (
            "an XML file (an ESI? 'ecatsim eeprom build' reads those)"
            if isinstance(data, str) and data.lstrip().startswith("<")
            else f"YAML of type {type(data).__name__}"
        )
        raise DescriptionError(
            f"{src}: not a device description: {what}; expected a YAML mapping with device:, "
            "identity:, ... as in config/tmc8670.yaml"
        )
    d = r.mapping(data, "", _TOP)
    dev = r.mapping(
        d.get("device", {}),
        "device",
        {"name", "order_code", "group", "group_name", "hardware_version", "software_version"},
    )
    idn = r.mapping(
        d.get("identity"), "identity", {"vendor_id", "product_code", "revision", "serial"}
    )
    esc = r.mapping(
        d.get("esc", {}),
        "esc",
        {
            "pdi_control",
            "pdi_config",
            "sync_impulse_length",
            "pdi_config2",
            "alias",
            "eeprom_size_kbit",
        },
    )
    mbx = r.mapping(
        d.get("mailbox", {}),
        "mailbox",
        {"rx", "tx", "bootstrap_rx", "bootstrap_tx", "protocols", "coe_details", "foe"},
    )
    protocols = tuple(mbx.get("protocols") or ())
    for p in protocols:
        if p not in MAILBOX_PROTOCOLS:
            raise r.err(
                "mailbox.protocols", f"unknown protocol {p!r} (use: {', '.join(MAILBOX_PROTOCOLS)})"
            )
    details = tuple(mbx.get("coe_details") or ())
    for p in details:
        if p not in COE_DETAILS:
            raise r.err(
                "mailbox.coe_details", f"unknown detail {p!r} (use: {', '.join(COE_DETAILS)})"
            )
    sms = []
    for i, s in enumerate(d.get("sync_managers") or []):
        path = f"sync_managers[{i}]"
        s = r.mapping(s, path, {"start", "length", "control", "enable", "type"})
        typ = r.str_(s, "type", path, "unused")
        if typ not in SM_TYPES:
            raise r.err(f"{path}.type", f"unknown SM type {typ!r} (use: {', '.join(SM_TYPES)})")
        sms.append(
            SmConfig(
                r.int_(s, "start", path, 0, 0xFFFF),
                r.int_(s, "length", path, 0, 0xFFFF),
                r.int_(s, "control", path, 0, 0xFF),
                r.int_(s, "enable", path, 0, 0xFF, 1),
                typ,
            )
        )
    fmmus = tuple(d.get("fmmus") or ())
    for f in fmmus:
        if f not in FMMU_TYPES:
            raise r.err("fmmus", f"unknown FMMU use {f!r} (use: {', '.join(FMMU_TYPES)})")
    dcs = []
    for i, m in enumerate(d.get("dc") or []):
        path = f"dc[{i}]"
        m = r.mapping(
            m,
            path,
            {
                "name",
                "description",
                "assign_activate",
                "sync0_cycle",
                "sync0_shift",
                "sync1_cycle",
                "sync1_shift",
            },
        )
        dcs.append(
            DcOpMode(
                r.str_(m, "name", path),
                r.str_(m, "description", path, ""),
                r.int_(m, "assign_activate", path, 0, 0xFFFF, 0),
                r.int_(m, "sync0_cycle", path, 0, 0xFFFFFFFF, 0),
                r.int_(m, "sync0_shift", path, -(2**31), 2**31 - 1, 0),
                r.int_(m, "sync1_cycle", path, 0, 0xFFFFFFFF, 0),
                r.int_(m, "sync1_shift", path, -(2**31), 2**31 - 1, 0),
            )
        )
    desc = DeviceDescription(
        source=src,
        name=r.str_(dev, "name", "device"),
        order_code=r.str_(dev, "order_code", "device", ""),
        group=r.str_(dev, "group", "device", ""),
        group_name=r.str_(dev, "group_name", "device", ""),
        hardware_version=r.str_(dev, "hardware_version", "device", ""),
        software_version=r.str_(dev, "software_version", "device", ""),
        identity=Identity(
            r.int_(idn, "vendor_id", "identity", 0, 0xFFFFFFFF),
            r.int_(idn, "product_code", "identity", 0, 0xFFFFFFFF),
            r.int_(idn, "revision", "identity", 0, 0xFFFFFFFF),
            r.int_(idn, "serial", "identity", 0, 0xFFFFFFFF, 0),
        ),
        esc=EscConfig(
            r.int_(esc, "pdi_control", "esc", 0, 0xFFFF, 0x0005),
            r.int_(esc, "pdi_config", "esc", 0, 0xFFFF, 0),
            r.int_(esc, "sync_impulse_length", "esc", 0, 0xFFFF, 0),
            r.int_(esc, "pdi_config2", "esc", 0, 0xFFFF, 0),
            r.int_(esc, "alias", "esc", 0, 0xFFFF, 0),
            r.int_(esc, "eeprom_size_kbit", "esc", 1, 4096, 32),
        ),
        mailbox=MailboxConfig(
            _area(r, mbx, "rx"),
            _area(r, mbx, "tx"),
            _area(r, mbx, "bootstrap_rx"),
            _area(r, mbx, "bootstrap_tx"),
            protocols,
            details,
            bool(mbx.get("foe", False)),
        ),
        sync_managers=tuple(sms),
        fmmus=fmmus,
        rxpdos=_pdos(r, d.get("rxpdos"), "rxpdos"),
        txpdos=_pdos(r, d.get("txpdos"), "txpdos"),
        dc=tuple(dcs),
        od_raw=d.get("od"),
        motor_raw=d.get("motor"),
        mfcio_config=_mfcio(r, d.get("mfcio")),
    )
    for i, s in enumerate(desc.sync_managers):
        want = {"pd_out": desc.rx_bytes, "pd_in": desc.tx_bytes}.get(s.type)
        if want is not None and s.length != want:
            raise r.err(
                f"sync_managers[{i}].length",
                f"{s.length} does not match the {s.type} PDOs ({want} bytes); set it to {want}",
            )
    return desc


def load_description(path: str | Path) -> DeviceDescription:
    """Read and validate a device description file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise DescriptionError(f"{p}: cannot read ({exc.strerror}); check the path") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise DescriptionError(f"{p}: not valid YAML ({getattr(exc, 'problem', exc)})") from exc
    return parse_description(data, p.name)


def default_description(name: str = "tmc8670.yaml") -> DeviceDescription:
    """A packaged description: config/tmc8670.yaml (the default) or config/tmc8460.yaml."""
    text = importlib.resources.files("ecatsim.defaults").joinpath(name).read_text()
    return parse_description(yaml.safe_load(text), name)


def with_protocol(desc: DeviceDescription, name: str) -> DeviceDescription:
    """``desc`` declaring mailbox protocol ``name`` too (SII word 0x1C, the ESI's
    ``<Mailbox>``), e.g. EoE for a slave configured with ``eoe:``. Ref: ETG.2010 Table 2."""
    mb = desc.mailbox
    if name in mb.protocols:
        return desc
    return replace(desc, mailbox=replace(mb, protocols=(*mb.protocols, name)))
