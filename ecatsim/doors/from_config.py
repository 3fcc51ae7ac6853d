"""Build the front doors a segment file lists beside its slaves (``tmcl:``, ``lin:``).

Each door package validates its own mapping: ``door_from_config(data, src, base)`` in the
package's ``server`` module returns a :class:`~ecatsim.doors.host.FrontDoor` or raises
:class:`~ecatsim.errors.UserError` with one line naming the file, the key and the fix.
"""

from __future__ import annotations

import importlib
import signal
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any, cast

import structlog

from ecatsim.doors.host import DoorHost, FrontDoor, serve_doors
from ecatsim.ethercat.eoe_tap import EoeTap
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import SegmentConfig
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.pdi_spi.external import ExternalFirmware
from ecatsim.pdi_spi.mfc import MfcSpi
from ecatsim.slave.eoe import find_eoe

DoorFactory = Callable[[dict[str, object], str, Path | None], FrontDoor]

#: the module holding each door's ``door_from_config``
FACTORIES: dict[str, str] = {
    "tmcl": "ecatsim.tmcl.server",
    "lin": "ecatsim.lin.server",
}


def _factory(key: str) -> DoorFactory:
    module = importlib.import_module(FACTORIES[key])
    return cast(DoorFactory, module.door_from_config)


def build_doors(cfg: SegmentConfig, segment: Segment | None = None) -> DoorHost | None:
    """The segment file's doors, the PDI sockets of its slaves with external firmware
    (``pdi<position>``), the MFC CTRL sockets of its TMC8460s (``mfc<position>``) and the
    TAP devices of its EoE slaves (``eoe<position>``), behind one :class:`DoorHost`; None
    if there are none."""
    built: dict[str, FrontDoor] = {}
    try:
        if segment is not None:
            for pos, fw in enumerate(segment.firmware):
                if isinstance(fw, ExternalFirmware):
                    built[f"pdi{pos}"] = fw
                elif isinstance(fw, MfcioBlock) and isinstance(fw.mcu, ExternalFirmware):
                    built[f"pdi{pos}"] = fw.mcu  # a TMC8460 with MFCIO and a microcontroller
                sock = cfg.slaves[pos].mfc_socket if pos < len(cfg.slaves) else None
                if sock is not None and isinstance(fw, MfcioBlock):
                    what = f"{cfg.source}: slaves[{pos}].mfc_socket"
                    built[f"mfc{pos}"] = MfcSpi(fw, sock, segment.clock, what)
                eoe = cfg.slaves[pos].eoe if pos < len(cfg.slaves) else None
                service = find_eoe(getattr(fw, "mbx", None))
                if eoe is not None and service is not None:
                    what = f"{cfg.source}: slaves[{pos}].eoe.tap"
                    built[f"eoe{pos}"] = EoeTap(eoe.tap, service, pos, what)
        if not cfg.doors and not built:
            return None
        for key, data in cfg.doors:
            built[key] = _factory(key)(data, cfg.source, cfg.base)
    except BaseException:
        for door in built.values():
            door.close()
        raise
    return DoorHost(built)


def serve_door(name: str, door: FrontDoor, ctl_path: Path, **ready: Any) -> None:
    """A daemon serving one front door (``ecatsim tmcl``, ``ecatsim lin``): its control
    socket at ``ctl_path``, one ``ready`` log line with ``ready``'s fields, the loop until
    SIGINT/SIGTERM; the socket and the door are closed however it ends."""
    from ecatsim.clock import MonotonicClock
    from ecatsim.ctl.server import ControlSocket

    host = DoorHost({name: door})
    try:
        sock = ControlSocket(ctl_path, None, None, host)
    except BaseException:
        host.close()
        raise
    stopping: list[int] = []

    def stop(signum: int, frame: FrameType | None) -> None:
        stopping.append(signum)

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    structlog.get_logger(f"ecatsim.{name}").info("ready", ctl=str(sock.path), **ready)
    try:
        serve_doors(
            host, MonotonicClock().now_ns, lambda: bool(stopping), {sock.fileno(): sock.serve}
        )
    finally:
        sock.close()
        host.close()
