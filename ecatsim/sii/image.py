"""SII EEPROM images: build from a device description, parse, and format for humans.

Layout: words 0x00-0x07 ESC configuration area (word 7 = CRC), 0x08-0x0F identity,
0x14-0x17 bootstrap mailbox, 0x18-0x1B standard mailbox, 0x1C mailbox protocols,
0x3E size, 0x3F version, categories from word 0x40 until type 0xFFFF.
Ref: ETG.2010 §2 (SII), Tables 2-20.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from ecatsim.device.description import FMMU_TYPES, DeviceDescription
from ecatsim.sii.crc import crc8

CAT_MFCIO = 1  # TMC8460 MFCIO configuration, first at word 0x40 (TMC8460 §6.3)
CAT_STRINGS = 10
CAT_DATATYPES = 20
CAT_GENERAL = 30
CAT_FMMU = 40
CAT_SYNCM = 41
CAT_TXPDO = 50
CAT_RXPDO = 51
CAT_DC = 60
CAT_END = 0xFFFF
CAT_NAMES = {
    CAT_STRINGS: "STRINGS",
    CAT_DATATYPES: "DATATYPES",
    CAT_GENERAL: "GENERAL",
    CAT_FMMU: "FMMU",
    CAT_SYNCM: "SYNCM",
    CAT_TXPDO: "TXPDO",
    CAT_RXPDO: "RXPDO",
    CAT_DC: "DC",
}
FIRST_CATEGORY_WORD = 0x40
#: string indices are one byte (ETG.2010 Table 4); index 0 is "no string"
MAX_STRINGS = 255
PROTOCOL_NAMES = ("AoE", "EoE", "CoE", "FoE", "SoE", "VoE")
SM_TYPE_NAMES = {0: "unused", 1: "mbx_out", 2: "mbx_in", 3: "pd_out", 4: "pd_in"}
FMMU_NAMES = {v: k for k, v in FMMU_TYPES.items()}


class SiiError(ValueError):
    """A malformed SII image; the message names the offset or category."""


class _Strings:
    def __init__(self) -> None:
        self.items: list[bytes] = []

    def idx(self, s: str) -> int:
        if not s:
            return 0
        b = s.encode("latin-1", "replace")[:255]
        if b not in self.items:
            if len(self.items) == MAX_STRINGS:
                return 0  # an index is one byte: names past the 255th stay unnamed
            self.items.append(b)
        return self.items.index(b) + 1

    def data(self) -> bytes:
        out = bytes([len(self.items)])
        for b in self.items:
            out += bytes([len(b)]) + b
        return out


def _cat(code: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return struct.pack("<HH", code, len(data) // 2) + data


def _pdo_cat(pdos: tuple, strings: _Strings) -> bytes:  # type: ignore[type-arg]
    out = b""
    for p in pdos:
        out += struct.pack("<HBBBBH", p.index, len(p.entries), p.sm, 0, strings.idx(p.name), 0)
        for e in p.entries:
            out += struct.pack(
                "<HBBBBH", e.index, e.subindex, strings.idx(e.name), e.type_code, e.bits, 0
            )
    return out


def build_image(
    desc: DeviceDescription, *, serial: int | None = None, alias: int | None = None
) -> bytes:
    """The SII image of a device description, padded with 0xFF to the EEPROM size.

    Ref: ETG.2010 Tables 2 (header), 4 (strings), 5 (general), 8 (FMMU), 9 (SyncM),
    10-12 (PDO), 13 (DC).
    """
    e = desc.esc
    idn = desc.identity
    mb = desc.mailbox
    size_bytes = e.eeprom_size_kbit * 128
    hdr = bytearray(128)
    struct.pack_into(
        "<HHHHH",
        hdr,
        0,
        e.pdi_control,
        e.pdi_config,
        e.sync_impulse_length,
        e.pdi_config2,
        e.alias if alias is None else alias,
    )
    hdr[14] = crc8(bytes(hdr[0:14]))
    struct.pack_into(
        "<IIII",
        hdr,
        0x10,
        idn.vendor_id,
        idn.product_code,
        idn.revision,
        idn.serial if serial is None else serial,
    )
    struct.pack_into(
        "<8HH",
        hdr,
        0x28,
        mb.bootstrap_rx.offset,
        mb.bootstrap_rx.size,
        mb.bootstrap_tx.offset,
        mb.bootstrap_tx.size,
        mb.rx.offset,
        mb.rx.size,
        mb.tx.offset,
        mb.tx.size,
        mb.protocol_bits,
    )
    struct.pack_into("<HH", hdr, 0x7C, e.eeprom_size_kbit - 1, 1)
    strings = _Strings()
    strings.idx(desc.name)  # string 1 is the device name (SOEM reads the name from it)
    general = bytearray(32)
    general[0] = strings.idx(desc.group)
    general[1] = 0
    general[2] = strings.idx(desc.order_code)
    general[3] = strings.idx(desc.name)
    general[5] = mb.coe_detail_bits if "coe" in mb.protocols else 0
    general[6] = 0x01 if mb.foe else 0
    general[7] = 0
    general[11] = 0
    struct.pack_into("<h", general, 12, 0)  # current on EBus: none (MII ports)
    general[14] = general[0]
    struct.pack_into("<H", general, 16, 0x0011)  # physical ports 0/1: MII
    cats = b""
    cats_after = _cat(CAT_GENERAL, bytes(general))
    fm = bytes(FMMU_TYPES[f] for f in desc.fmmus)
    if len(fm) % 2:
        fm += b"\xff"  # padding byte, not an FMMU
    cats_after += _cat(CAT_FMMU, fm)
    sm = b"".join(
        struct.pack("<HHBBBB", s.start, s.length, s.control, 0, s.enable, s.type_code)
        for s in desc.sync_managers
    )
    cats_after += _cat(CAT_SYNCM, sm)
    if desc.txpdos:
        cats_after += _cat(CAT_TXPDO, _pdo_cat(desc.txpdos, strings))
    if desc.rxpdos:
        cats_after += _cat(CAT_RXPDO, _pdo_cat(desc.rxpdos, strings))
    if desc.dc:
        dc = b""
        for m in desc.dc:
            dc += struct.pack(
                "<IiihHhBB4x",
                m.sync0_cycle,
                m.sync0_shift,
                m.sync1_shift,
                0,
                m.assign_activate,
                0,
                strings.idx(m.name),
                strings.idx(m.description),
            )
        cats_after += _cat(CAT_DC, dc)
    cats = _cat(CAT_STRINGS, strings.data()) + cats_after + struct.pack("<H", CAT_END)
    if desc.mfcio_config:  # the TMC8460 loads it only as the first category (§6.3)
        cats = _cat(CAT_MFCIO, desc.mfcio_config) + cats
    img = bytes(hdr) + cats
    if len(img) > size_bytes:
        raise SiiError(f"image of {len(img)} bytes does not fit a {e.eeprom_size_kbit} kbit EEPROM")
    return img + b"\xff" * (size_bytes - len(img))


@dataclass
class SiiImage:
    """A decoded SII image."""

    words: tuple[int, ...]
    crc_ok: bool
    vendor_id: int
    product_code: int
    revision: int
    serial: int
    mailbox: tuple[int, ...]  # bootstrap rx/tx, standard rx/tx offsets and sizes
    protocols: int
    size_kbit: int
    version: int
    strings: list[str] = field(default_factory=list)
    categories: list[tuple[int, int, bytes]] = field(
        default_factory=list
    )  # (type, word addr, data)
    general: dict[str, int] = field(default_factory=dict)
    fmmus: list[int] = field(default_factory=list)
    sms: list[tuple[int, int, int, int, int, int]] = field(default_factory=list)
    pdos: list[tuple[str, int, str, int, list[tuple[int, int, str, int, int]]]] = field(
        default_factory=list
    )
    dc: list[tuple[int, int, int, int, str]] = field(default_factory=list)

    def string(self, idx: int) -> str:
        return self.strings[idx - 1] if 0 < idx <= len(self.strings) else ""

    @property
    def name(self) -> str:
        return self.string(self.general.get("name_idx", 0))


def parse_image(data: bytes) -> SiiImage:
    """Decode an SII image. Raises SiiError (only) for anything malformed."""
    if len(data) < FIRST_CATEGORY_WORD * 2 + 2:
        raise SiiError(f"image too short: {len(data)} bytes, the header alone is 128")
    if len(data) % 2:
        raise SiiError(f"odd image length {len(data)}: an SII image is made of 16-bit words")
    words = struct.unpack_from("<64H", data, 0)
    vid, pid, rev, ser = struct.unpack_from("<IIII", data, 0x10)
    img = SiiImage(
        words=words,
        crc_ok=crc8(bytes(data[0:14])) == data[14],
        vendor_id=vid,
        product_code=pid,
        revision=rev,
        serial=ser,
        mailbox=tuple(words[0x14:0x1C]),
        protocols=words[0x1C],
        size_kbit=words[0x3E] + 1,
        version=words[0x3F],
    )
    w = FIRST_CATEGORY_WORD
    nwords = len(data) // 2
    while True:
        if w >= nwords:
            raise SiiError(f"no end marker (0xFFFF) before the end of the image at word 0x{w:04X}")
        typ = struct.unpack_from("<H", data, w * 2)[0]
        if typ == CAT_END:
            break
        if w + 2 > nwords:
            raise SiiError(f"category header at word 0x{w:04X} runs past the end")
        ln = struct.unpack_from("<H", data, w * 2 + 2)[0]
        start = (w + 2) * 2
        end = start + ln * 2
        if end > len(data):
            raise SiiError(
                f"category {CAT_NAMES.get(typ, typ)} at word 0x{w:04X} ({ln} words) "
                "runs past the end"
            )
        img.categories.append((typ, w, bytes(data[start:end])))
        w += 2 + ln
    for typ, w, body in img.categories:
        _decode(img, typ, w, body)
    return img


def _decode(img: SiiImage, typ: int, w: int, body: bytes) -> None:
    where = f"category {CAT_NAMES.get(typ, typ)} at word 0x{w:04X}"
    try:
        if typ == CAT_STRINGS:
            n = body[0] if body else 0
            p = 1
            for i in range(n):
                if p >= len(body):
                    raise SiiError(f"{where}: string {i + 1} of {n} runs past the category")
                ln = body[p]
                if p + 1 + ln > len(body):
                    raise SiiError(f"{where}: string {i + 1} runs past the category")
                img.strings.append(body[p + 1 : p + 1 + ln].decode("latin-1"))
                p += 1 + ln
        elif typ == CAT_GENERAL:
            if len(body) < 16:
                raise SiiError(f"{where}: {len(body)} bytes, expected 32")
            img.general = {
                "group_idx": body[0],
                "image_idx": body[1],
                "order_idx": body[2],
                "name_idx": body[3],
                "coe_details": body[5],
                "foe_details": body[6],
                "eoe_details": body[7],
                "flags": body[11],
                "ebus_current": struct.unpack_from("<h", body, 12)[0],
            }
        elif typ == CAT_FMMU:
            img.fmmus = [b for b in body if b != 0xFF]
        elif typ == CAT_SYNCM:
            for i in range(len(body) // 8):
                img.sms.append(struct.unpack_from("<HHBBBB", body, i * 8))
        elif typ in (CAT_TXPDO, CAT_RXPDO):
            p = 0
            kind = "TxPDO" if typ == CAT_TXPDO else "RxPDO"
            while p + 8 <= len(body):
                idx, n, sm, _sync, name, _flags = struct.unpack_from("<HBBBBH", body, p)
                p += 8
                entries = []
                for _ in range(n):
                    if p + 8 > len(body):
                        raise SiiError(f"{where}: PDO 0x{idx:04X} entries run past the category")
                    ei, es, en, et, eb, _ef = struct.unpack_from("<HBBBBH", body, p)
                    entries.append((ei, es, img.string(en), et, eb))
                    p += 8
                img.pdos.append((kind, idx, img.string(name), sm, entries))
        elif typ == CAT_DC:
            for i in range(len(body) // 24):
                c0, s0, s1, _f1, act, _f0, name, _desc = struct.unpack_from(
                    "<IiihHhBB", body, i * 24
                )
                img.dc.append((c0, s0, s1, act, img.string(name)))
    except struct.error as exc:
        raise SiiError(f"{where}: truncated ({exc})") from exc


def format_image(img: SiiImage) -> str:
    """Human-readable decode for ``ecatsim eeprom show``."""
    crc = img.words[7] & 0xFF
    lines = [
        "SII header",
        f"  PDI control        0x{img.words[0]:04X}",
        f"  PDI configuration  0x{img.words[1]:04X}",
        f"  SYNC pulse length  {img.words[2]} x 10 ns",
        f"  station alias      0x{img.words[4]:04X}",
        f"  checksum           0x{crc:02X} ({'ok' if img.crc_ok else 'BAD'})",
        f"  vendor id          0x{img.vendor_id:08X}",
        f"  product code       0x{img.product_code:08X} ({img.product_code})",
        f"  revision           0x{img.revision:08X}",
        f"  serial             0x{img.serial:08X} ({img.serial})",
        "  bootstrap mailbox  rx 0x{:04X}/{} tx 0x{:04X}/{}".format(*img.mailbox[0:4]),
        "  standard mailbox   rx 0x{:04X}/{} tx 0x{:04X}/{}".format(*img.mailbox[4:8]),
        "  mailbox protocols  "
        + (", ".join(n for i, n in enumerate(PROTOCOL_NAMES) if img.protocols >> i & 1) or "none"),
        f"  size               {img.size_kbit} kbit, version {img.version}",
    ]
    for typ, w, body in img.categories:
        name = "MFCIO" if typ == CAT_MFCIO else CAT_NAMES.get(typ, str(typ))
        lines.append(f"category {name} (type {typ}) at word 0x{w:04X}, {len(body) // 2} words")
        if typ == CAT_MFCIO:
            from ecatsim.mfcio.config import describe

            if w != FIRST_CATEGORY_WORD:
                lines.append("  (not at word 0x0040: the TMC8460 does not load it)")
            lines += describe(body)
        elif typ == CAT_STRINGS:
            lines += [f"  [{i + 1}] {s!r}" for i, s in enumerate(img.strings)]
        elif typ == CAT_GENERAL:
            g = img.general
            lines.append(
                f"  name {img.name!r}, order {img.string(g['order_idx'])!r}, "
                f"group {img.string(g['group_idx'])!r}"
            )
            lines.append(
                f"  CoE details 0x{g['coe_details']:02X}, FoE details 0x{g['foe_details']:02X}"
            )
        elif typ == CAT_FMMU:
            lines += [f"  FMMU{i}: {FMMU_NAMES.get(t, t)}" for i, t in enumerate(img.fmmus)]
        elif typ == CAT_SYNCM:
            for i, (st, ln, ctl, _s, en, t) in enumerate(img.sms):
                lines.append(
                    f"  SM{i}: start 0x{st:04X} length {ln} control 0x{ctl:02X} enable {en} "
                    f"type {SM_TYPE_NAMES.get(t, t)}"
                )
    for kind, idx, name, sm, entries in img.pdos:
        lines.append(f"  {kind} 0x{idx:04X} {name!r} on SM{sm}")
        for ei, es, ename, et, eb in entries:
            lines.append(f"    0x{ei:04X}:{es:02X} {eb:2d} bit type 0x{et:04X} {ename!r}")
    for c0, s0, _s1, act, name in img.dc:
        lines.append(
            f"  DC opmode {name!r}: assign activate 0x{act:04X}, SYNC0 cycle {c0} ns, shift {s0} ns"
        )
    return "\n".join(lines)
