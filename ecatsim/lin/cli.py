"""``ecatsim lin``: a LIN bus of TMC211 nodes on a pseudo-terminal."""

from __future__ import annotations

from pathlib import Path

import click
import structlog

from ecatsim.errors import UserError
from ecatsim.logsetup import configure_logging, log_format_option

log = structlog.get_logger("ecatsim.lin")


@click.command("lin")
@click.option(
    "--pty",
    "pty",
    type=click.Path(path_type=Path),
    help="Where to link the bus's pty (the master opens it as its serial port). "
    "Default: the config's 'pty:'.",
)
@click.option(
    "--config",
    "config_path",
    type=click.Path(path_type=Path),
    help="Bus YAML (nodes, HW pins, OTP; see config/lin-bus.yaml). Default: one TMC211, "
    "HW0..2 = 0, OTP all zero.",
)
@click.option(
    "--ctl",
    "ctl",
    type=click.Path(path_type=Path),
    help="Control socket path (0600; default: the runtime dir, named after the pty).",
)
@log_format_option
def lin(pty: Path | None, config_path: Path | None, ctl: Path | None, log_format: str) -> None:
    """Serve TMC211 LIN nodes on a pty until SIGINT/SIGTERM.

    The master writes a frame as break (the byte 0x00), sync 0x55, protected identifier
    and, for frames it publishes, data and classic checksum; for the nodes' frames it
    writes the header only and reads the answer. `ecatsim ctl door lin help` lists the
    control commands (temperature, voltage, coil faults, switch, stops).
    """
    from ecatsim.clock import MonotonicClock
    from ecatsim.ctl.server import default_path
    from ecatsim.doors.from_config import serve_door
    from ecatsim.lin.config import BusConfig, load_bus
    from ecatsim.lin.server import LinDoor

    configure_logging(log_format)
    cfg = load_bus(config_path) if config_path is not None else BusConfig()
    link = pty or cfg.pty
    if link is None:
        raise UserError("ecatsim lin: give --pty PATH (or 'pty:' in the --config file)")
    door = LinDoor(cfg, link, MonotonicClock())
    try:
        serve_door(
            "lin",
            door,
            ctl or default_path(f"lin-{link.name}"),
            pty=str(link),
            nodes=[f"{n.name}@0x{n.address:02X}" for n in door.bus.nodes],
            baud=cfg.baud,
        )
    finally:
        p = door.bus.parser
        log.info("stopped", frames=p.frames, errors=p.errors, noise=p.noise)
