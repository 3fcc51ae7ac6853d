"""Assemble a segment from its configuration: per slave an ESC, its EEPROM, the firmware
behind the PDI and the device behind the firmware."""

from __future__ import annotations

import struct
from collections.abc import Callable
from functools import partial
from pathlib import Path

import structlog

from ecatsim import topology
from ecatsim.clock import Clock
from ecatsim.config import SegmentConfig, SlaveConfig
from ecatsim.description import (
    DescriptionError,
    DeviceDescription,
    default_description,
    load_description,
)
from ecatsim.device.drive import Drive
from ecatsim.device.echo import EchoDevice
from ecatsim.device.factory import make_coe_device
from ecatsim.errors import UserError
from ecatsim.esc.core import Esc, FrameContext
from ecatsim.esc.pdi import Pdi
from ecatsim.esi import EsiError, read_esi
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.mfcio.parts import parse_wiring
from ecatsim.pdi_spi.external import ExternalFirmware
from ecatsim.pdi_spi.protocol import SpiTiming
from ecatsim.segment import Segment, Serviceable
from ecatsim.sii.image import SiiError, build_image
from ecatsim.sii.store import EepromStore
from ecatsim.slave.al import AlState
from ecatsim.slave.app import Application
from ecatsim.slave.coe import CoeProtocol
from ecatsim.slave.emcy import Emergency
from ecatsim.slave.firmware import Firmware, MailboxLayout
from ecatsim.slave.foe import FoeServer
from ecatsim.slave.mailbox import MailboxEngine
from ecatsim.slave.od_build import build_od
from ecatsim.slave.pdo import PdoImage
from ecatsim.wire.mailbox import MbxType

log = structlog.get_logger("ecatsim.build")

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


def _image(sc: SlaveConfig, desc: DeviceDescription) -> bytearray:
    if sc.esi is not None:
        try:
            desc = read_esi(sc.esi)
        except EsiError as exc:
            raise UserError(str(exc)) from exc
    if sc.eeprom is not None and sc.eeprom.exists():
        try:
            return EepromStore.load(sc.eeprom)
        except SiiError as exc:
            raise UserError(str(exc)) from exc
    img = build_image(desc, serial=sc.serial, alias=sc.alias)
    if sc.eeprom is not None:
        try:
            EepromStore.save(sc.eeprom, img)
        except OSError as exc:
            raise UserError(
                f"{sc.eeprom}: cannot create the EEPROM image ({exc.strerror})"
            ) from exc
        log.info("eeprom_created", path=str(sc.eeprom))
    return bytearray(img)


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
    escs: list[Esc] = []
    firmware: list[Serviceable] = []
    paths: list[Path | None] = []
    for i, sc in enumerate(cfg.slaves):
        desc = _description(sc, cache)
        image = _image(sc, desc)
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
            # no firmware behind the PDI: the ESC runs in device emulation (SII word 0) and
            # the MFCIO block serves the memory blocks (TMC8460 §6.1, §6.5)
            wiring = parse_wiring(sc.mfcio, cfg.source, f"slaves[{i}].mfcio")
            block = MfcioBlock(pdi, wiring, clock.now_ns())
            esc.on_reset = block.reset
            escs.append(esc)
            firmware.append(block)
            paths.append(sc.eeprom)
            continue
        fw: Serviceable
        if sc.firmware == "external" and sc.pdi_socket is not None:
            what = f"{cfg.source}: slaves[{i}].pdi_socket"
            fw = ExternalFirmware(pdi, sc.pdi_socket, clock, SpiTiming(), what)
        elif "coe" in desc.mailbox.protocols:
            base = sc.description.parent if sc.description is not None else None
            try:
                od = build_od(desc, base)
            except DescriptionError as exc:
                raise UserError(str(exc)) from exc
            mbx = MailboxEngine(pdi)
            emcy = Emergency(mbx, od)
            try:
                device = make_coe_device(sc.device, desc, od, emcy)
            except DescriptionError as exc:
                raise UserError(str(exc)) from exc
            app: Application = PdoImage(od, device)
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
    seg.awake = frozenset(i for i, fw in enumerate(firmware) if isinstance(fw, MfcioBlock))
    return seg
