"""The device behind a CoE slave's firmware, by device type, with its motor parameters
from the description's ``motor:`` section."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from ecatsim.device.description import DescriptionError, DeviceDescription
from ecatsim.device.drive import Drive
from ecatsim.device.echo import OdEchoDevice
from ecatsim.device.servo import MotorParams
from ecatsim.slave.emcy import Emergency
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.pdo import CoeDevice

#: the motor constants the servo divides by (servo.py: the winding's time constant L / R,
#: the current's R, the acceleration 1 / J, the substep): zero is no motor
DIVISORS = frozenset({"inductance", "inertia", "resistance", "substep"})


def motor_params(raw: Any, src: str) -> MotorParams:
    """``motor:`` keys are MotorParams fields; one-line errors name the key. Numbers are
    finite and not negative, and the servo's divisors (``DIVISORS``) positive."""
    if raw is None:
        return MotorParams()
    if not isinstance(raw, dict):
        raise DescriptionError(f"{src}: motor: expected a mapping")
    names = {f.name: f for f in dataclasses.fields(MotorParams)}
    kw: dict[str, Any] = {}
    for k, v in raw.items():
        if k not in names:
            raise DescriptionError(f"{src}: motor.{k}: unknown key (allowed: {', '.join(names)})")
        default = names[k].default
        if isinstance(default, str):
            if v not in ("pmsm", "stepper"):
                raise DescriptionError(f"{src}: motor.{k}: use pmsm or stepper")
        elif isinstance(default, int) and not isinstance(default, bool):
            if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
                raise DescriptionError(f"{src}: motor.{k}: expected a positive integer, got {v!r}")
        elif not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
            raise DescriptionError(f"{src}: motor.{k}: expected a number, got {v!r}")
        elif k in DIVISORS and v <= 0:
            raise DescriptionError(f"{src}: motor.{k}: expected a number > 0, got {v!r}")
        elif v < 0:
            raise DescriptionError(f"{src}: motor.{k}: expected a number >= 0, got {v!r}")
        kw[k] = v
    return MotorParams(**kw)


def make_coe_device(
    kind: str,
    desc: DeviceDescription,
    od: ObjectDictionary,
    emcy: Emergency,
    slave: int | None = None,
) -> CoeDevice:
    """tmc8670: the CiA 402 drive (logging as ``slave``, its position); echo: the loopback
    device."""
    if kind == "echo":
        return OdEchoDevice(od)
    params = motor_params(desc.motor_raw, desc.source)
    return Drive(od, params, emcy.raise_error, emcy.clear, slave=slave)
