"""A description's ``motor:`` section: every bad value is one line naming the file, the key
and what it takes; the servo's divisors must be positive (zero would be no motor, and a
division by zero in the drive's cycle)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from ecatsim.clock import ManualClock
from ecatsim.device.description import DescriptionError
from ecatsim.device.factory import DIVISORS, motor_params
from ecatsim.device.servo import MotorParams
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import parse_segment

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"inertia": 0}, "d.yaml: motor.inertia: expected a number > 0, got 0"),
        ({"resistance": 0.0}, "d.yaml: motor.resistance: expected a number > 0, got 0.0"),
        ({"inductance": -1e-3}, "d.yaml: motor.inductance: expected a number > 0, got -0.001"),
        ({"substep": 0}, "d.yaml: motor.substep: expected a number > 0, got 0"),
        ({"viscous": -1.0}, "d.yaml: motor.viscous: expected a number >= 0, got -1.0"),
        ({"coulomb": math.nan}, "d.yaml: motor.coulomb: expected a number, got nan"),
        ({"kt": math.inf}, "d.yaml: motor.kt: expected a number, got inf"),
        ({"load": True}, "d.yaml: motor.load: expected a number, got True"),
        ({"kt": "0.05"}, "d.yaml: motor.kt: expected a number, got '0.05'"),
        ({"ppr": 0}, "d.yaml: motor.ppr: expected a positive integer, got 0"),
        ({"pole_pairs": True}, "d.yaml: motor.pole_pairs: expected a positive integer, got True"),
        ({"volts": 24}, "d.yaml: motor.volts: unknown key (allowed: motor_type, pole_pairs, "),
    ],
)
def test_a_bad_motor_value_is_one_line(raw: dict[str, object], message: str) -> None:
    with pytest.raises(DescriptionError) as e:
        motor_params(raw, "d.yaml")
    assert str(e.value).startswith(message)
    assert "\n" not in str(e.value)


def test_zero_where_the_servo_does_not_divide_is_a_motor() -> None:
    p = motor_params({"viscous": 0, "coulomb": 0.0, "load": 0, "kt": 0.08}, "d.yaml")
    assert (p.viscous, p.coulomb, p.load, p.kt) == (0, 0.0, 0, 0.08)
    assert {f for f in MotorParams.__dataclass_fields__} >= DIVISORS


def test_a_segment_with_a_zero_inertia_motor_is_refused(tmp_path: Path) -> None:
    """The one line comes at load, not as a division by zero in the first cycle."""
    desc = yaml.safe_load((ROOT / "config" / "tmc8670.yaml").read_text())
    desc["motor"] = {"inertia": 0}
    (tmp_path / "slow.yaml").write_text(yaml.safe_dump(desc))
    seg = {"slaves": [{"device": "tmc8670", "description": "slow.yaml"}]}
    with pytest.raises(UserError) as e:
        build_segment(parse_segment(seg, "seg.yaml", tmp_path), ManualClock(0))
    assert str(e.value).endswith("motor.inertia: expected a number > 0, got 0")
    assert "slow.yaml" in str(e.value)
