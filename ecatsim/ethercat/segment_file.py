"""The segment description (YAML): which slaves, in wire order, with what device.

Every problem is one line naming the file, the key path and the fix.

```yaml
slaves:
  - device: tmc8670          # device type: tmc8670 | echo | tmc8460 (MFCIO block, no MCU)
    count: 2                 # optional: this entry repeated (serials counted up)
    description: my.yaml     # optional device description (default: the packaged TMC8670)
    eeprom: drive.bin        # optional SII image file; master writes persist to it
    alias: 0                 # optional configured station alias (SII word 4)
    serial: 1                # optional serial number (SII words 0x0E/0x0F)
    dc_drift_ppm: 0.0        # optional local clock drift
    firmware: external       # optional: the slave firmware runs outside ecatsim ...
    pdi_socket: /run/fw.sock # ... and drives the chip over this PDI SPI socket
    pdi_emulation: false     # optional: the PDI_EMULATION pin (0x0141 bit 0 until the
                             # EEPROM is loaded)
    mfcio: {...}             # tmc8460 only: parts on the MFCIO pins (ecatsim/mfcio/parts.py)
    mfc_socket: /run/mfc.sock  # tmc8460 only: the MFC CTRL SPI on a socket (TMC8460 §3.6)
    eoe:                     # tmc8670 or ESI slave, optional: Ethernet over EtherCAT (ETG.1000.6
      tap: eoe0              # §5.7): the slave's network, a TAP device the daemon creates
      ip: 10.77.0.2/24       # ... optional address of it (EoE Set IP Parameter changes it)
      mac: 02:00:00:00:00:02 # ... optional MAC address of it
    port3: [{device: echo}]  # optional: a junction's sub-chain on port 3 (processed first)
    port2: [{device: echo}]  # optional: ... and on port 2 (processed after port 1's line)
  - esi: vendor.xml          # no device: a generic slave, everything from the ESI
    device_type: EL1234      # which device of the file: its <Type> text, or ...
    product: 0x04d23052      # ... its ProductCode / RevisionNo
    revision: 0x00100000
    signals:                 # optional: inputs driven without a test (ecatsim/generic/signals.py)
      - {input: "0x6000:01", loopback: "0x7000:01"}
out_iface: eth1              # optional: port 1 of the last slave leaves on this interface
                             # (the next daemon, more slaves, the master's second NIC)
faults:                      # optional: faults injected while running (ecatsim/faults/spec.py)
  - {kind: wkc, value: -1, count: 3, on_state: op}
  - {kind: drop, probability: 0.001, seed: 7}
tmcl: {...}                  # optional: TMCL modules served beside the segment (ecatsim tmcl)
lin: {...}                   # optional: a LIN bus of TMC211 nodes served beside it (ecatsim lin)
```
"""

from __future__ import annotations

import importlib.resources
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ecatsim.errors import UserError
from ecatsim.ethercat import topology
from ecatsim.faults.spec import FaultSpec, FaultSpecError, parse_fault

DEVICE_TYPES = ("tmc8670", "echo", "tmc8460", "generic")
#: the front doors a segment file may list beside its slaves
DOOR_KEYS = ("tmcl", "lin")
MAX_SLAVES = 4096

_SLAVE_KEYS = {
    "device",
    "count",
    "description",
    "eeprom",
    "esi",
    "alias",
    "serial",
    "dc_drift_ppm",
    "name",
    "foe_dir",
    "foe_password",
    "firmware",
    "pdi_socket",
    "pdi_emulation",
    "mfcio",
    "mfc_socket",
    "device_type",
    "product",
    "revision",
    "signals",
    "eoe",
    "port2",
    "port3",
}
_EOE_KEYS = ("tap", "ip", "mac")
#: who runs the slave firmware behind the PDI: ecatsim, or a program on the PDI socket
FIRMWARE_KINDS = ("ecatsim", "external")


@dataclass(frozen=True, slots=True)
class EoeConfig:
    """A slave's EoE endpoint: its TAP device and the addresses it starts with."""

    tap: str
    #: IPv4 address and mask, network order; None: none until the master sets one
    ip: bytes | None = None
    mask: bytes | None = None
    mac: bytes | None = None


@dataclass(frozen=True, slots=True)
class SlaveConfig:
    """One slave of the segment."""

    device: str = "tmc8670"
    description: Path | None = None
    eeprom: Path | None = None
    esi: Path | None = None
    alias: int | None = None
    serial: int | None = None
    dc_drift_ppm: float = 0.0
    name: str | None = None
    foe_dir: Path | None = None
    foe_password: int = 0
    #: ``external``: ecatsim's firmware does not run; a program drives the chip over the
    #: PDI SPI socket ``pdi_socket`` (TMC8460 §3.5)
    firmware: str = "ecatsim"
    pdi_socket: Path | None = None
    #: the PDI_EMULATION pin, 0x0141 bit 0 before the EEPROM loads (TMC8460 §5.26)
    pdi_emulation: bool = False
    #: device tmc8460: the parts wired to the MFCIO pins (validated when built)
    mfcio: dict[str, object] | None = None
    #: device tmc8460: the MFC CTRL SPI on this socket (TMC8460 §3.6)
    mfc_socket: Path | None = None
    #: device generic: which device of the ESI (<Type> text, ProductCode, RevisionNo)
    device_type: str | None = None
    product: int | None = None
    revision: int | None = None
    #: device generic: inputs driven without a test (validated when built)
    signals: tuple[object, ...] | None = None
    #: device generic from an ENI: the model made for it (ecatsim/ethercat/eni.py)
    model: object | None = None
    #: Ethernet over EtherCAT (ETG.1000.6 §5.7): the slave's TAP device and addresses
    eoe: EoeConfig | None = None


@dataclass(frozen=True, slots=True)
class SegmentConfig:
    """The whole segment."""

    slaves: tuple[SlaveConfig, ...]
    source: str = "<default>"
    faults: tuple[FaultSpec, ...] = field(default_factory=tuple)
    #: the front doors besides EtherCAT, by key (``tmcl``, ``lin``): their YAML mapping as
    #: written, validated by the door itself when it is built (ecatsim/doors/from_config.py)
    doors: tuple[tuple[str, dict[str, object]], ...] = ()
    #: the directory relative paths in the file are taken from
    base: Path | None = None
    #: per slave (in processing order) its ports' cables (ecatsim/ethercat/topology.py); empty: a
    #: line, port 1 of each slave to port 0 of the next
    wiring: tuple[tuple[int, ...], ...] = ()
    #: per slave the ports it has (bit p); empty: ports 0 and 1 everywhere
    ports: tuple[int, ...] = ()
    #: port 1 of the last slave leaves on this interface (None: it is closed)
    out_iface: str | None = None


def _err(src: str, key: str, msg: str) -> UserError:
    return UserError(f"{src}: {key}: {msg}")


def _int(src: str, key: str, v: object, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise _err(src, key, f"expected an integer {lo}..{hi}, got {v!r}")
    return v


def _path(src: str, base: Path | None, key: str, v: object) -> Path:
    if not isinstance(v, str) or not v:
        raise _err(src, key, f"expected a file path, got {v!r}")
    p = Path(v)
    if not p.is_absolute() and base is not None:
        p = base / p
    return p


def _ipv4(text: str) -> bytes | None:
    parts = text.split(".")
    if len(parts) != 4 or not all(p.isdigit() and int(p) <= 255 for p in parts):
        return None
    return bytes(int(p) for p in parts)


def parse_eoe(src: str, key: str, v: object) -> EoeConfig:
    """``eoe: {tap: NAME, ip: A.B.C.D/LEN, mac: 02:00:00:00:00:01}``."""
    if not isinstance(v, dict):
        raise _err(src, key, "expected a mapping like {tap: eoe0, ip: 10.77.0.2/24}")
    bad = sorted(set(v) - set(_EOE_KEYS))
    if bad:
        raise _err(src, f"{key}.{bad[0]}", f"unknown key (allowed: {', '.join(_EOE_KEYS)})")
    tap = v.get("tap")
    if not isinstance(tap, str) or not 1 <= len(tap) <= 15 or "/" in tap or " " in tap:
        raise _err(
            src, f"{key}.tap", f"expected an interface name of 1..15 characters, got {tap!r}"
        )
    ip = mask = mac = None
    if "ip" in v:
        text = v["ip"]
        addr, _, plen = str(text).partition("/")
        ip = _ipv4(addr)
        if not isinstance(text, str) or ip is None or not plen.isdigit() or int(plen) > 32:
            raise _err(
                src,
                f"{key}.ip",
                f"expected an address with its prefix like 10.77.0.2/24, got {text!r}",
            )
        bits = (0xFFFFFFFF << (32 - int(plen))) & 0xFFFFFFFF
        mask = bits.to_bytes(4, "big")
    if "mac" in v:
        text = v["mac"]
        octets = str(text).split(":")
        try:
            mac = bytes(int(o, 16) for o in octets)
        except ValueError:
            mac = None
        if (
            not isinstance(text, str)
            or mac is None
            or len(mac) != 6
            or any(len(o) != 2 for o in octets)
            or mac[0] & 1
        ):
            raise _err(
                src, f"{key}.mac", f"expected a unicast MAC like 02:00:00:00:00:02, got {text!r}"
            )
    return EoeConfig(tap, ip, mask, mac)


def parse_segment(data: object, src: str, base: Path | None = None) -> SegmentConfig:
    """Validate a loaded YAML document into a SegmentConfig."""
    if not isinstance(data, dict):
        raise UserError(f"{src}: expected a mapping with a 'slaves:' list at the top level")
    top = ("slaves", "faults", *DOOR_KEYS, "eni", "esi_dir", "out_iface")
    unknown = set(data) - set(top)
    if unknown:
        k = sorted(unknown)[0]
        raise _err(src, k, f"unknown key (allowed: {', '.join(top)})")
    if "eni" in data:
        if "slaves" in data:
            raise _err(src, "eni", "the ENI lists the slaves: give eni: or slaves:, not both")
        from ecatsim.ethercat.eni import eni_segment_slaves

        esi_dir = _path(src, base, "esi_dir", data["esi_dir"]) if "esi_dir" in data else None
        eni = _path(src, base, "eni", data["eni"])
        data = {**data, "slaves": eni_segment_slaves(eni, esi_dir)}
    doors: list[tuple[str, dict[str, object]]] = []
    for k in DOOR_KEYS:
        if k in data:
            if not isinstance(data[k], dict):
                raise _err(src, k, f"expected a mapping (see 'ecatsim {k} --help')")
            doors.append((k, data[k]))
    raw = data.get("slaves")
    out: list[SlaveConfig] = []
    wiring: list[list[int]] = []
    ports: list[int] = []
    if isinstance(raw, tuple):  # made from an ENI: a line of slaves
        out.extend(raw)
        wiring = topology.linear(len(out))
        ports = [0x3] * len(out)
    else:
        _chain(src, base, raw, "slaves", out, wiring, ports, topology.MAIN)
    out_iface = data.get("out_iface")
    if out_iface is not None:
        if not isinstance(out_iface, str) or not out_iface:
            raise _err(src, "out_iface", f"expected an interface name, got {out_iface!r}")
        wiring[0 if not wiring else _last_of_line(wiring)][1] = topology.OUT
    if len(out) > MAX_SLAVES:
        raise _err(src, "slaves", f"at most {MAX_SLAVES} slaves")
    taps = [sc.eoe.tap for sc in out if sc.eoe is not None]
    for i, sc in enumerate(out):
        if sc.eoe is not None and taps.count(sc.eoe.tap) > 1:
            raise _err(
                src, f"slaves[{i}].eoe.tap", f"{sc.eoe.tap} is named twice: one TAP per slave"
            )
    faults = data.get("faults") or []
    if not isinstance(faults, list):
        raise _err(src, "faults", "expected a list of faults like {kind: drop, after_frames: 100}")
    specs: list[FaultSpec] = []
    for i, f in enumerate(faults):
        try:
            specs.append(parse_fault(f))
        except FaultSpecError as exc:
            raise _err(src, f"faults[{i}]", str(exc)) from None
    linear = all(p == 0x3 for p in ports)
    return SegmentConfig(
        tuple(out),
        src,
        tuple(specs),
        tuple(doors),
        base,
        wiring=() if linear and out_iface is None else tuple(tuple(w) for w in wiring),
        ports=() if linear else tuple(ports),
        out_iface=out_iface,
    )


def load_segment(path: Path) -> SegmentConfig:
    """Read and validate a segment YAML file."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise UserError(
            f"{path}: cannot read the segment file ({exc.strerror}); check the path"
        ) from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise UserError(f"{path}:{where}: not valid YAML ({getattr(exc, 'problem', exc)})") from exc
    return parse_segment(data, str(path), path.parent)


def default_segment() -> SegmentConfig:
    """The embedded default segment (config/segment.yaml): one TMC8670 drive."""
    text = importlib.resources.files("ecatsim.defaults").joinpath("segment.yaml").read_text()
    return parse_segment(yaml.safe_load(text), "segment.yaml (embedded default)")


def repeat_default(n: int) -> SegmentConfig:
    """``--slaves N``: the default device N times with distinct serial numbers."""
    if not 1 <= n <= MAX_SLAVES:
        raise UserError(f"--slaves: expected 1..{MAX_SLAVES}, got {n}")
    base = default_segment().slaves[0]
    first = base.serial if base.serial is not None else 1
    slaves = tuple(
        SlaveConfig(
            device=base.device,
            description=base.description,
            alias=base.alias,
            serial=first + i,
            dc_drift_ppm=base.dc_drift_ppm,
        )
        for i in range(n)
    )
    return SegmentConfig(slaves, f"--slaves {n}")


def _last_of_line(wiring: list[list[int]]) -> int:
    """The last slave of the main line (from slave 0 along port 1)."""
    i = 0
    while wiring[i][1] >= 0:
        i = wiring[i][1] // 4
    return i


def _chain(
    src: str,
    base: Path | None,
    raw: object,
    where: str,
    out: list[SlaveConfig],
    wiring: list[list[int]],
    ports: list[int],
    up: int,
) -> None:
    """Parse a line of slaves (``where``: its key), cabled port 1 to port 0, the first's
    port 0 to ``up``; a junction's ``port3``/``port2`` lines are parsed where a frame
    reaches them, so a slave's index is its position with every link up
    (ecatsim/ethercat/topology.py: 0 -> 3 -> 1 -> 2)."""
    if not isinstance(raw, list) or not raw:
        raise _err(src, where, "expected a non-empty list of slaves")
    prev = -1
    branches: list[tuple[int, str, object]] = []
    for i, s in enumerate(raw):
        key = f"{where}[{i}]"
        if not isinstance(s, dict):
            raise _err(src, key, "expected a mapping like {device: tmc8670}")
        bad = set(s) - _SLAVE_KEYS
        if bad:
            k = sorted(bad)[0]
            raise _err(
                src, f"{key}.{k}", f"unknown key (allowed: {', '.join(sorted(_SLAVE_KEYS))})"
            )
        dev = s.get("device", "generic" if "esi" in s else "tmc8670")
        if dev not in DEVICE_TYPES:
            raise _err(
                src,
                f"{key}.device",
                f"unknown device {dev!r} (use one of: {', '.join(DEVICE_TYPES)})",
            )
        count = _int(src, f"{key}.count", s.get("count", 1), 1, MAX_SLAVES)
        desc = (
            _path(src, base, f"{key}.description", s["description"]) if "description" in s else None
        )
        eeprom = _path(src, base, f"{key}.eeprom", s["eeprom"]) if "eeprom" in s else None
        esi = _path(src, base, f"{key}.esi", s["esi"]) if "esi" in s else None
        alias = _int(src, f"{key}.alias", s["alias"], 0, 0xFFFF) if "alias" in s else None
        serial = _int(src, f"{key}.serial", s["serial"], 0, 0xFFFFFFFF) if "serial" in s else None
        drift = s.get("dc_drift_ppm", 0.0)
        if isinstance(drift, bool) or not isinstance(drift, int | float) or abs(drift) > 1000:
            raise _err(src, f"{key}.dc_drift_ppm", f"expected a number -1000..1000, got {drift!r}")
        foe_dir = _path(src, base, f"{key}.foe_dir", s["foe_dir"]) if "foe_dir" in s else None
        foe_pw = _int(src, f"{key}.foe_password", s.get("foe_password", 0), 0, 0xFFFFFFFF)
        name = s.get("name")
        if name is not None and not isinstance(name, str):
            raise _err(src, f"{key}.name", f"expected a string, got {name!r}")
        if eeprom is not None and count > 1:
            raise _err(src, f"{key}.eeprom", "one EEPROM file cannot back count > 1 slaves")
        firmware = s.get("firmware", "ecatsim")
        if firmware not in FIRMWARE_KINDS:
            raise _err(
                src, f"{key}.firmware", f"use one of: {', '.join(FIRMWARE_KINDS)}, got {firmware!r}"
            )
        pdi_socket = (
            _path(src, base, f"{key}.pdi_socket", s["pdi_socket"]) if "pdi_socket" in s else None
        )
        if (firmware == "external") != (pdi_socket is not None):
            raise _err(
                src,
                f"{key}.pdi_socket",
                "firmware: external and pdi_socket: PATH go together (the socket the "
                "firmware connects to)",
            )
        pdi_emulation = s.get("pdi_emulation", False)
        if not isinstance(pdi_emulation, bool):
            raise _err(
                src, f"{key}.pdi_emulation", f"expected true or false, got {pdi_emulation!r}"
            )
        if pdi_socket is not None and count > 1:
            raise _err(src, f"{key}.pdi_socket", "one PDI socket cannot serve count > 1 slaves")
        mfcio = s.get("mfcio")
        if mfcio is not None and (dev != "tmc8460" or not isinstance(mfcio, dict)):
            raise _err(src, f"{key}.mfcio", "a mapping, for device: tmc8460 only")
        mfc_socket = (
            _path(src, base, f"{key}.mfc_socket", s["mfc_socket"]) if "mfc_socket" in s else None
        )
        if mfc_socket is not None and (dev != "tmc8460" or count > 1):
            raise _err(src, f"{key}.mfc_socket", "one socket, for one device: tmc8460 slave")
        if dev == "generic" and "esi" not in s:
            raise _err(src, f"{key}.device", "a generic slave needs esi: FILE (its ESI)")
        for k in ("device_type", "product", "revision", "signals"):
            if k in s and dev != "generic":
                raise _err(src, f"{key}.{k}", "for a generic slave only (esi: without device:)")
        device_type = s.get("device_type")
        if device_type is not None and not isinstance(device_type, str):
            raise _err(src, f"{key}.device_type", f"expected the <Type> text, got {device_type!r}")
        product = (
            _int(src, f"{key}.product", s["product"], 0, 0xFFFFFFFF) if "product" in s else None
        )
        revision = (
            _int(src, f"{key}.revision", s["revision"], 0, 0xFFFFFFFF) if "revision" in s else None
        )
        signals = s.get("signals")
        if signals is not None and not isinstance(signals, list):
            raise _err(src, f"{key}.signals", "expected a list like [{input: ENTRY, counter: {}}]")
        eoe = parse_eoe(src, f"{key}.eoe", s["eoe"]) if "eoe" in s else None
        if eoe is not None and (
            count > 1 or dev not in ("tmc8670", "generic") or firmware != "ecatsim"
        ):
            raise _err(
                src,
                f"{key}.eoe",
                "one TAP device serves one slave: a tmc8670 or an ESI slave with count 1 and "
                "ecatsim's firmware",
            )
        for j in range(count):
            out.append(
                SlaveConfig(
                    device=dev,
                    description=desc,
                    eeprom=eeprom,
                    esi=esi,
                    alias=alias,
                    serial=None if serial is None else serial + j,
                    dc_drift_ppm=float(drift),
                    name=name,
                    foe_dir=None
                    if foe_dir is None
                    else (foe_dir / f"slave{len(out)}" if count > 1 else foe_dir),
                    foe_password=foe_pw,
                    firmware=firmware,
                    pdi_socket=pdi_socket,
                    pdi_emulation=pdi_emulation,
                    mfcio=mfcio,
                    mfc_socket=mfc_socket,
                    device_type=device_type,
                    product=product,
                    revision=revision,
                    signals=tuple(signals) if signals is not None else None,
                    eoe=eoe,
                )
            )
        junction = "port2" in s or "port3" in s
        if junction and count > 1:
            raise _err(src, f"{key}.count", "a junction (port2/port3) cannot repeat")
        for j in range(count):
            k = len(out) - count + j
            _cable(wiring, k, up if prev < 0 else 4 * prev + 1)
            ports.append(0xF if junction else 0x3)
            prev = k
        if "port3" in s:
            _chain(src, base, s["port3"], f"{key}.port3", out, wiring, ports, 4 * prev + 3)
        if "port2" in s:
            branches.append((prev, f"{key}.port2", s["port2"]))
    for k, bkey, sub in reversed(branches):
        _chain(src, base, sub, bkey, out, wiring, ports, 4 * k + 2)


def _cable(wiring: list[list[int]], k: int, up: int) -> None:
    """Slave ``k``'s port 0 to ``up`` (an ESC port, or topology.MAIN), both ends."""
    while len(wiring) <= k:
        wiring.append([topology.NONE] * 4)
    wiring[k][0] = up
    if up >= 0:
        wiring[up // 4][up % 4] = 4 * k
