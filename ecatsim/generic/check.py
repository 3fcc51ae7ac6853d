"""``ecatsim esi check``: every device of every ESI built in process and brought to OP by
the minimal master; one line per device, one line for a file that cannot be read.

Ref: ETG.2000 §5 (Descriptions/Devices); ETG.1000.6 §6.4 (AL state machine).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import structlog

from ecatsim.clock import ManualClock
from ecatsim.device.esi import EsiError, device_ids, parse_root
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig
from ecatsim.generic.minimaster import BringUpError, MiniMaster

log = structlog.get_logger("ecatsim.esi_check")


def check_device(path: Path, tname: str, product: int, revision: int) -> tuple[str, bool]:
    """One device: ``ok: OP, ...`` or what failed."""
    sc = SlaveConfig(
        device="generic", esi=path, device_type=tname, product=product, revision=revision
    )
    try:
        seg = build_segment(SegmentConfig((sc,), str(path)), ManualClock(1_000_000_000))
        return "ok: " + MiniMaster(seg).to_op(0), True
    except (UserError, BringUpError) as exc:
        return f"FAILED: {exc}", False
    except Exception as exc:  # a bug in ecatsim: one line, and the traceback in the log
        log.error("esi_check_internal_error", esi=str(path), device=tname, exc_info=exc)
        return f"FAILED: internal error {exc!r}", False


def check_files(paths: list[Path]) -> Iterator[tuple[str, bool]]:
    """(line, ok) per device of each file; one line for a file that cannot be read."""
    for path in paths:
        try:
            root = parse_root(path)
            devices = device_ids(root, path)
        except EsiError as exc:
            msg = str(exc).removeprefix(f"{path}: ")
            yield f"{path}: FAILED: {msg}", False
            continue
        for _d, tname, pc, rv in devices:
            line, ok = check_device(path, tname, pc, rv)
            yield f"{path}: {tname} (0x{pc:08X}/0x{rv:08X}): {line}", ok
