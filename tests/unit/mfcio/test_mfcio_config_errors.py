"""A bad MFCIO configuration is one line naming the file, the key and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from ecatsim.clock import ManualClock
from ecatsim.device.description import DescriptionError, parse_description
from ecatsim.errors import UserError
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment_file import parse_segment


def build(data: object) -> None:
    build_segment(parse_segment(data, "seg.yaml", Path(".")), ManualClock(0))


@pytest.mark.parametrize(
    ("slave", "message"),
    [
        (
            {"device": "tmc8670", "mfcio": {}},
            "seg.yaml: slaves[0].mfcio: a mapping, for device: tmc8460 only",
        ),
        (
            {"device": "tmc8460", "mfcio": {"spi": ["loopback", "flash"]}},
            "seg.yaml: slaves[0].mfcio.spi: expected a list of up to 4 of loopback, "
            "register_file, none (CS0 first)",
        ),
        (
            {"device": "tmc8460", "mfcio": {"stepper": {"full_steps": 0}}},
            "seg.yaml: slaves[0].mfcio.stepper.full_steps: expected a positive integer, got 0",
        ),
        (
            {"device": "tmc8460", "mfcio": {"gpio": {9: 1}}},
            "seg.yaml: slaves[0].mfcio.gpio: pin 9: expected 0..7",
        ),
        (
            {"device": "tmc8460", "mfcio": {"nes": 2}},
            "seg.yaml: slaves[0].mfcio.nes: expected 0 or 1, got 2",
        ),
        (
            {"device": "tmc8460", "mfcio": {"motor": 1}},
            "seg.yaml: slaves[0].mfcio.motor: unknown key (allowed: stepper, encoder, spi, "
            "gpio, nes)",
        ),
    ],
)
def test_segment_errors(slave: dict[str, object], message: str) -> None:
    with pytest.raises(UserError) as e:
        build({"slaves": [slave]})
    assert str(e.value) == message


MINIMAL = {"device": {"name": "x"}, "identity": {"vendor_id": 1, "product_code": 2, "revision": 3}}


@pytest.mark.parametrize(
    ("mfcio", "message"),
    [
        (
            {"registers": {"ENC_MOD": 0x10}},
            "d.yaml: mfcio.registers.ENC_MOD: unknown MFCIO register",
        ),
        ({"default": 0x20}, "d.yaml: mfcio.default: expected an integer 0..31, got 32"),
        ({"config": "zz"}, "d.yaml: mfcio.config: 'zz' is not hex bytes like 1E0000101E10"),
        ({"config": "10" * 45}, "d.yaml: mfcio.config: 45 bytes: at most 44"),
    ],
)
def test_description_errors(mfcio: object, message: str) -> None:
    with pytest.raises(DescriptionError) as e:
        parse_description({**MINIMAL, "mfcio": mfcio}, "d.yaml")
    assert str(e.value).startswith(message)


def test_description_vector() -> None:
    d = parse_description(
        {**MINIMAL, "mfcio": {"registers": {"ENC_MODE": 0x1E, "ENC_X": 0x10}}}, "d"
    )
    assert d.mfcio_config == bytes([0x1E, 0, 0, 0x10])
    d = parse_description({**MINIMAL, "mfcio": {"config": "1E0000101E"}}, "d")
    assert d.mfcio_config == bytes.fromhex("1E0000101E00")
