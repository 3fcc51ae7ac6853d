"""``ecatsim tmcl``: serve emulated TMCM-1311 modules over TMCL until SIGINT/SIGTERM."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import click
import structlog
import yaml

from ecatsim.errors import UserError
from ecatsim.logsetup import configure_logging, log_format_option

log = structlog.get_logger("ecatsim.tmcl")


def _load(path: Path) -> dict[str, Any]:
    """A YAML file holding a ``tmcl:`` mapping (a segment file) or just that mapping."""
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise UserError(f"--config {path}: cannot read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise UserError(f"--config {path}: not YAML ({exc})") from exc
    if isinstance(data, dict) and isinstance(data.get("tmcl"), dict):
        data = data["tmcl"]
    if not isinstance(data, dict):
        raise UserError(f"--config {path}: expected a mapping with a tmcl: key")
    return data


@click.command("tmcl")
@click.option(
    "--listen",
    "listen",
    multiple=True,
    help="tcp://HOST:PORT or pty:PATH (repeatable; each is a line every module is on).",
)
@click.option("--config", "config_path", type=click.Path(path_type=Path), help="YAML (tmcl:).")
@click.option(
    "--eeprom",
    type=click.Path(path_type=Path),
    help="Configuration EEPROM file: STAP/STGP values survive restarts.",
)
@click.option(
    "--module-address",
    "addresses",
    type=click.IntRange(0, 255),
    multiple=True,
    help="Serve a module at this serial address (repeatable; default 1).",
)
@click.option(
    "--ctl",
    "ctl_path",
    type=click.Path(path_type=Path),
    help="Control socket path (default: RUNDIR/tmcl.sock).",
)
@log_format_option
def tmcl(
    listen: tuple[str, ...],
    config_path: Path | None,
    eeprom: Path | None,
    addresses: tuple[int, ...],
    ctl_path: Path | None,
    log_format: str,
) -> None:
    """Emulate TMCM-1311 closed-loop stepper modules speaking TMCL.

    \b
    ecatsim tmcl --listen tcp://127.0.0.1:2323
    ecatsim tmcl --listen pty:/tmp/tmcm1311 --eeprom tmcm.json --module-address 1 \\
                 --module-address 2
    """
    from ecatsim.ctl.server import default_path
    from ecatsim.doors.from_config import serve_door
    from ecatsim.tmcl.server import TmclDoor, parse_config

    configure_logging(log_format, logging.INFO)
    data: dict[str, Any] = _load(config_path) if config_path is not None else {}
    src = str(config_path) if config_path is not None else "command line"
    base = config_path.parent if config_path is not None else None
    if listen:
        data["listen"] = list(listen)
    if addresses:
        data["modules"] = [{"address": a} for a in addresses]
    if eeprom is not None:
        data["eeprom"] = str(eeprom.resolve())
    if not data.get("listen"):
        raise UserError("give --listen tcp://HOST:PORT or --listen pty:PATH (or a --config)")
    modules, urls, eeprom_path = parse_config(data, src, base)
    door = TmclDoor(modules, urls, eeprom_path, base=base)
    try:
        serve_door(
            "tmcl",
            door,
            ctl_path or default_path("tmcl"),
            listen=door.status()["listen"],
            modules=[m.address for m in door.modules],
            eeprom=str(eeprom_path) if eeprom_path else None,
        )
    finally:
        log.info("stopped", frames=door.frames, bad_checksums=door.bad_checksums)
