"""What the drive's twin tests compare (tests/unit/device): a logger that records every
call, and a drive's whole observable state (OD values, cycle fields, servo, profile,
faults)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ecatsim.device.drive import Drive

#: the profile generator's fields (pp)
PROFILE = ("pos", "vel", "target", "vmax", "acc", "dec")


class Log:
    """The drive's logger: every call recorded."""

    def __init__(self, out: list[Any]) -> None:
        self.out = out

    def info(self, event: str, **kw: object) -> None:
        self.out.append(("info", event, tuple(sorted(kw.items()))))

    def warning(self, event: str, **kw: object) -> None:
        self.out.append(("warning", event, tuple(sorted(kw.items()))))


def drive_state(d: Drive, fields: Sequence[str], servo: Sequence[str]) -> tuple[object, ...]:
    """Every OD value (the published ones flushed first), the drive's ``fields``, the
    servo's ``servo`` fields, the profile and the active faults."""
    d.pub_flush()
    values = [(o.index, s, e.value) for o in d.od.objects.values() for s, e in o.entries.items()]
    return (
        values,
        [getattr(d, k) for k in fields],
        [getattr(d.servo, k) for k in servo],
        [getattr(d.profile, k) for k in PROFILE],
        sorted(d.active_faults),
    )
