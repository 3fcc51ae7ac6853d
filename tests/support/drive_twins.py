"""What the drive's twin tests compare (tests/unit/device): a logger that records every
call, and a drive's whole observable state (OD values, cycle fields, servo, profile,
faults)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ecatsim.device.drive import Drive
from ecatsim.slave.al import AlState

#: the drive's cycle fields and the servo's state, compared between twins
FIELDS = ("state", "mode", "prev_cw", "p_demand", "v_demand_rpm", "v_ff_rpm", "set_point_ack",
          "homing_done", "homing_active", "fault_code", "last_target", "t_ns")  # fmt: skip
SERVO = ("angle", "omega", "iq_ma", "iq_integ", "integ", "iq_ref_ma", "id_ma", "id_integ")
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


def drive_state(d: Drive, fields: Sequence[str] = FIELDS,
                servo: Sequence[str] = SERVO) -> tuple[object, ...]:  # fmt: skip
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


def perturb(d: Drive, sets: dict[int, int], fault: float, al: float, t: int,
            release: float) -> None:  # fmt: skip
    """One step of a twin walk before the cycle: the OD writes ``sets`` (in order), an
    overcurrent raised (``fault`` < 0.01) or released (< ``release``), the AL state to
    SAFEOP (``al`` < 0.01) or OP (< 0.03) at ``t``."""
    for index, value in sets.items():
        d.od.set(index, 0, value)
    if fault < 0.01:
        d.inject("overcurrent")
    elif fault < release:
        d.inject("overcurrent", False)
    if al < 0.01:
        d.al_state_changed(AlState.SAFEOP, t)
    elif al < 0.03:
        d.al_state_changed(AlState.OP, t)
