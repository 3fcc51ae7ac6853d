"""Assemble a segment from its configuration: per slave an ESC, its EEPROM, the firmware
behind the PDI and the device behind the firmware."""

from __future__ import annotations

import dataclasses
import struct
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import structlog

from ecatsim.clock import Clock
from ecatsim.device.description import (
    DescriptionError,
    DeviceDescription,
    default_description,
    load_description,
    with_protocol,
)
from ecatsim.device.drive import Drive
from ecatsim.device.echo import EchoDevice
from ecatsim.device.esi import EsiError, read_esi
from ecatsim.device.factory import make_coe_device
from ecatsim.errors import UserError
from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.pdi import EV_SM0, Pdi
from ecatsim.ethercat import topology
from ecatsim.ethercat.schedule import Serviceable
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig
from ecatsim.generic.device import GenericDevice, signals_of
from ecatsim.generic.model import GenericModel, from_esi
from ecatsim.generic.pinio import PinIo
from ecatsim.generic.signals import SignalError
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.mfcio.parts import parse_wiring
from ecatsim.pdi_spi.external import ExternalFirmware
from ecatsim.pdi_spi.protocol import SpiTiming
from ecatsim.sii.image import SiiError, build_image
from ecatsim.sii.store import EepromStore
from ecatsim.slave.al import AlState
from ecatsim.slave.app import Application
from ecatsim.slave.coe import CoeProtocol
from ecatsim.slave.emcy import Emergency
from ecatsim.slave.eoe import EoeService
from ecatsim.slave.firmware import Firmware, MailboxLayout
from ecatsim.slave.foe import FoeServer
from ecatsim.slave.mailbox import SM_IN, MailboxEngine
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import CoeDevice, PdoImage, PdoRules
from ecatsim.wire.eoe import IpParams
from ecatsim.wire.mailbox import MbxType

log = structlog.get_logger("ecatsim.ethercat.assembly")

#: Distinct local clock start per slave, so DC offsets are meaningful (ns).
DC_START_STEP_NS = 1_000_003_000

#: the latch unit the drive's encoder index pulse is wired to (SII 0x0151 bit 6 = 0)
INDEX_LATCH_UNIT = 1


def mailbox_layout(image: bytes | bytearray) -> MailboxLayout:
    """Mailbox offsets/sizes from SII words 0x14-0x1B. Ref: ETG.2010 Table 2."""
    if len(image) < 0x38:
        return MailboxLayout(0, 0, 0, 0)
    b_rx_o, b_rx_s, b_tx_o, b_tx_s, rx_o, rx_s, tx_o, tx_s = struct.unpack_from("<8H", image, 0x28)
    return MailboxLayout(rx_o, rx_s, tx_o, tx_s, b_rx_o, b_rx_s, b_tx_o, b_tx_s)


def make_device(kind: str, desc: DeviceDescription) -> Application:
    """The application behind the firmware for a device type."""
    rx = [(e.index, e.bits) for p in desc.rxpdos for e in p.entries]
    tx = [(e.index, e.bits) for p in desc.txpdos for e in p.entries]
    return EchoDevice(rx, tx)


def _accept_for(fw: Firmware) -> Callable[[int], bool]:
    """In BOOT only FoE is served. Ref: ETG.1000.6 §6.4.1 (bootstrap state)."""

    def accept(mtype: int) -> bool:
        return fw.state != AlState.BOOT or mtype == MbxType.FOE

    return accept


def add_eoe(fw: Firmware, mbx: MailboxEngine, sc: SlaveConfig) -> EoeService:
    """The EoE service beside CoE/FoE; frames from the slave's network wake the firmware's
    mailbox service as an SM1 event would. Ref: ETG.1000.6 §5.7."""
    eoe = sc.eoe
    assert eoe is not None
    service = EoeService(mbx, IpParams(mac=eoe.mac, ip=eoe.ip, subnet=eoe.mask))
    ev_sm1 = EV_SM0 << SM_IN  # the event of SM1 (mailbox in) read by the master
    pdi = fw.pdi

    def kick() -> None:
        # with an event of its own pending the firmware serves the mailbox itself next
        # (after its SM activation handling, which must see the SM registers first)
        if not pdi.al_event() & fw.event_mask:
            fw.service_mailbox(ev_sm1, 0)

    service.kick = kick
    return service


class _Persist:
    def __init__(self, escs: list[Esc], paths: list[Path | None]) -> None:
        self.escs = escs
        self.paths = paths

    def __call__(self, pos: int) -> None:
        path = self.paths[pos]
        if path is None:
            return
        try:
            EepromStore.save(path, bytes(self.escs[pos].eeprom.image))
        except OSError as exc:
            log.error("eeprom_persist_failed", slave=pos, path=str(path), error=str(exc))


#: the packaged description of a device type without its own ``description:``
DEFAULT_DESCRIPTIONS = {"tmc8460": "tmc8460.yaml"}


def _description(
    sc: SlaveConfig, cache: dict[tuple[str, Path | None], DeviceDescription]
) -> DeviceDescription:
    key = (sc.device if sc.description is None else "", sc.description)
    if key not in cache:
        try:
            cache[key] = (
                default_description(DEFAULT_DESCRIPTIONS.get(sc.device, "tmc8670.yaml"))
                if sc.description is None
                else load_description(sc.description)
            )
        except DescriptionError as exc:
            raise UserError(str(exc)) from exc
    return cache[key]


#: EEPROM sizes a slave may have, in kbit (ETG.2010 word 0x3E: size in kbit - 1)
EEPROM_KBIT = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096)


def esi_image(desc: DeviceDescription, source: str, **kw: int | None) -> bytes:
    """The SII image of an ESI's device; an EEPROM the ESI declares too small for it gets
    the next standard size up, with one warning (hand-written ESIs often do)."""
    try:
        return build_image(desc, **kw)
    except SiiError as exc:
        error = exc
    for kbit in EEPROM_KBIT:
        if kbit <= desc.esc.eeprom_size_kbit:
            continue
        try:
            img = build_image(replace_size(desc, kbit), **kw)
        except SiiError as exc:
            error = exc
            continue
        log.warning(
            "eeprom_size_raised",
            esi=source,
            declared_bytes=desc.esc.eeprom_size_kbit * 128,
            used_bytes=kbit * 128,
        )
        return img
    raise UserError(f"{source}: {error}")


def replace_size(desc: DeviceDescription, kbit: int) -> DeviceDescription:
    return dataclasses.replace(desc, esc=dataclasses.replace(desc.esc, eeprom_size_kbit=kbit))


def _image(sc: SlaveConfig, desc: DeviceDescription, generic: bool = False) -> bytearray:
    from_esi_file = generic
    if sc.esi is not None and not generic:
        try:
            desc = read_esi(sc.esi)
        except EsiError as exc:
            raise UserError(str(exc)) from exc
        from_esi_file = True
    if sc.eoe is not None:
        desc = with_protocol(desc, "eoe")  # SII word 0x1C declares EoE (ETG.2010 Table 2)
    if sc.eeprom is not None and sc.eeprom.exists():
        try:
            return EepromStore.load(sc.eeprom)
        except SiiError as exc:
            raise UserError(str(exc)) from exc
    if from_esi_file:
        img = esi_image(desc, desc.source, serial=sc.serial, alias=sc.alias)
    else:
        try:
            img = build_image(desc, serial=sc.serial, alias=sc.alias)
        except SiiError as exc:  # a description whose SII does not fit its EEPROM size
            where = sc.esi or sc.description or f"the {sc.device} description"
            raise UserError(f"{where}: {exc}") from exc
    if sc.eeprom is not None:
        try:
            EepromStore.save(sc.eeprom, img)
        except OSError as exc:
            raise UserError(
                f"{sc.eeprom}: cannot create the EEPROM image ({exc.strerror})"
            ) from exc
        log.info("eeprom_created", path=str(sc.eeprom))
    return bytearray(img)


def generic_model(
    sc: SlaveConfig, cache: dict[tuple[object, ...], GenericModel], where: str
) -> GenericModel:
    """The model of a generic slave: from its ENI (made there) or its ESI (read once per
    file and device); what it does not model is one warning."""
    if isinstance(sc.model, GenericModel):
        return sc.model
    assert sc.esi is not None  # config: a generic slave has an esi
    key = (sc.esi, sc.product, sc.revision, sc.device_type)
    if key not in cache:
        try:
            hint = f"pick one with {where}.device_type (or product:/revision:)"
            model = from_esi(sc.esi, sc.product, sc.revision, sc.device_type, hint=hint)
        except EsiError as exc:
            raise UserError(str(exc)) from exc
        if model.warnings:
            log.warning("esi_not_modelled", esi=str(sc.esi), constructs=model.warnings)
        cache[key] = model
    return cache[key]


def _signals(sc: SlaveConfig, od: ObjectDictionary, src: str, i: int) -> list[Any]:
    try:
        return signals_of(list(sc.signals) if sc.signals is not None else None, od,
                          f"{src}: slaves[{i}].signals")  # fmt: skip
    except SignalError as exc:
        raise UserError(str(exc)) from exc


def segment_wiring(cfg: SegmentConfig, out: bool) -> list[list[int]]:
    """The cabling of the segment file, with port 1 of the main line's last slave to the
    out interface if ``out`` (``--out-iface``) or the file says so."""
    n = len(cfg.slaves)
    wiring = [list(w) for w in cfg.wiring] if cfg.wiring else topology.linear(n)
    if out and topology.out_port(wiring) is None:
        i = 0
        while wiring[i][1] >= 0:
            i = wiring[i][1] // 4
        wiring[i][1] = topology.OUT
    return wiring


def build_segment(cfg: SegmentConfig, clock: Clock, out: bool = False) -> Segment:
    """Build the ESCs, firmware and devices of a segment (``out``: with an out
    interface at port 1 of the main line's last slave)."""
    ctx = FrameContext()
    cache: dict[tuple[str, Path | None], DeviceDescription] = {}
    models: dict[tuple[object, ...], GenericModel] = {}
    escs: list[Esc] = []
    firmware: list[Serviceable] = []
    paths: list[Path | None] = []
    for i, sc in enumerate(cfg.slaves):
        model = generic_model(sc, models, f"slaves[{i}]") if sc.device == "generic" else None
        desc = model.desc if model is not None else _description(sc, cache)
        image = _image(sc, desc, model is not None)
        esc = Esc(
            i,
            ctx,
            image,
            dc_start_ns=(i + 1) * DC_START_STEP_NS,
            dc_drift_ppm=sc.dc_drift_ppm,
            pdi_emulation=sc.pdi_emulation,
        )
        pdi = Pdi(esc)
        layout = mailbox_layout(image)
        if sc.device == "tmc8460":
            # the MFCIO block serves the memory blocks (TMC8460 §6.1, §6.5); without a
            # microcontroller the ESC runs in device emulation (SII word 0)
            wiring = parse_wiring(sc.mfcio, cfg.source, f"slaves[{i}].mfcio")
            block = MfcioBlock(pdi, wiring, clock.now_ns())
            if sc.firmware == "external" and sc.pdi_socket is not None:
                # a microcontroller on the PDI SPI beside the MFCIO block (§3.1.2, decision
                # M32): its socket is served, the block sees its chip select (§6.4)
                what = f"{cfg.source}: slaves[{i}].pdi_socket"
                mcu = ExternalFirmware(pdi, sc.pdi_socket, clock, SpiTiming(), what)
                mcu.chip_select = block
                block.mcu = mcu
            esc.on_reset = block.reset
            escs.append(esc)
            firmware.append(block)
            paths.append(sc.eeprom)
            continue
        fw: Serviceable
        if model is not None and sc.eoe is not None and "coe" not in desc.mailbox.protocols:
            raise UserError(
                f"{cfg.source}: slaves[{i}].eoe: EoE shares the mailbox of a CoE slave, and "
                f"{sc.esi} gives this device none: remove eoe: or pick a device with CoE"
            )
        if sc.firmware == "external" and sc.pdi_socket is not None:
            what = f"{cfg.source}: slaves[{i}].pdi_socket"
            fw = ExternalFirmware(pdi, sc.pdi_socket, clock, SpiTiming(), what)
        elif model is not None and not desc.mailbox.protocols:
            # no mailbox, no microcontroller: the ESC in device emulation, the process image
            # of the ESI's PDOs (through an OD nobody serves) on the ESI's SMs
            od = model.build_od()
            gdev = GenericDevice(od, _signals(sc, od, cfg.source, i))
            sm_of = {s.type: n for n, s in reversed(list(enumerate(desc.sync_managers)))}
            fw = PinIo(pdi, PdoImage(od, gdev, model.rules), sm_of.get("pd_out"),
                       sm_of.get("pd_in"))  # fmt: skip
        elif model is not None and "coe" not in desc.mailbox.protocols:
            # a mailbox without CoE: the firmware, its PDOs from the ESI alone
            od = model.build_od()
            gdev = GenericDevice(od, _signals(sc, od, cfg.source, i))
            fw = gfw = Firmware(pdi, PdoImage(od, gdev, model.rules), layout)
            gfw.od = od
            gfw.device = gdev
        elif "coe" in desc.mailbox.protocols:
            if model is not None:
                od = model.build_od()
                if sc.serial is not None and 0x1018 in od and 4 in od[0x1018].entries:
                    od.set(0x1018, 4, sc.serial)
                rules = model.rules
            else:
                base = sc.description.parent if sc.description is not None else None
                try:
                    od = build_od(desc, base)
                except DescriptionError as exc:
                    raise UserError(str(exc)) from exc
                rules = PdoRules()
            mbx = MailboxEngine(pdi)
            emcy = Emergency(mbx, od)
            device: CoeDevice
            try:
                if model is not None:
                    device = GenericDevice(od, _signals(sc, od, cfg.source, i))
                else:
                    device = make_coe_device(sc.device, desc, od, emcy, slave=i)
            except DescriptionError as exc:
                raise UserError(str(exc)) from exc
            app: Application = PdoImage(od, device, rules)
            foe = desc.mailbox.foe or "foe" in desc.mailbox.protocols
            fw = coe_fw = Firmware(pdi, app, layout, mbx=mbx, bootstrap_supported=foe)
            coe_fw.coe = CoeProtocol(mbx, od, coe_fw.al_state_code)
            coe_fw.od = od
            coe_fw.emergency = emcy
            coe_fw.device = device
            if isinstance(device, Drive):
                # the board wires the encoder index to LATCH1 (decision D14)
                device.index_output = partial(pdi.latch_input, INDEX_LATCH_UNIT)
            if foe:
                server = FoeServer(coe_fw.al_state_code, mbx.max_body, sc.foe_dir, sc.foe_password)
                mbx.register(MbxType.FOE, server.handle)
            if sc.eoe is not None:
                add_eoe(coe_fw, mbx, sc)
            elif model is not None and "eoe" in desc.mailbox.protocols:
                log.warning("eoe_not_served", slave=i, esi=str(sc.esi),
                            fix="give the slave eoe: {tap: NAME} to serve its EoE")  # fmt: skip
            mbx.accept = _accept_for(coe_fw)
        else:
            fw = Firmware(pdi, make_device(sc.device, desc), layout)
        esc.on_reset = fw.reset
        escs.append(esc)
        firmware.append(fw)
        paths.append(sc.eeprom)
    seg = Segment(
        escs,
        ctx,
        clock,
        firmware,
        _Persist(escs, paths),
        wiring=segment_wiring(cfg, out),
        ports=cfg.ports,
    )
    awake = (i for i, fw in enumerate(firmware) if isinstance(fw, MfcioBlock | PinIo))
    seg.schedule.awake = frozenset(awake)
    return seg
