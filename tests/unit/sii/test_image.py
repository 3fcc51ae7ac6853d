"""SII image: CRC, exact header words, round trip, decoding errors, atomic store.

Ref: ETG.2010 §2 (SII layout, checksum); TMC8670 §4.1.6 (identity).
"""

from __future__ import annotations

import os
import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ecatsim.device.description import DescriptionError, default_description, parse_description
from ecatsim.sii.crc import crc8
from ecatsim.sii.image import SiiError, build_image, format_image, parse_image
from ecatsim.sii.store import EepromStore


def crc_reference(data: bytes) -> int:
    """Bit-by-bit CRC-8, polynomial x^8+x^2+x+1, initial value 0xFF."""
    c = 0xFF
    for b in data:
        for i in range(7, -1, -1):
            bit = ((c >> 7) ^ (b >> i)) & 1
            c = ((c << 1) & 0xFF) ^ (0x07 if bit else 0)
    return c


def test_crc_matches_reference() -> None:
    v = bytes([0x05, 0x00, 0x03, 0x0E, 0x64, 0x00, 0, 0, 0, 0, 0, 0, 0, 0])
    assert crc8(v) == crc_reference(v)
    assert crc8(b"") == 0xFF
    for n in range(0, 256, 17):
        d = bytes((n + i) & 0xFF for i in range(14))
        assert crc8(d) == crc_reference(d)


def test_default_image_header_words() -> None:
    img = build_image(default_description())
    assert len(img) == 4096
    w = struct.unpack_from("<64H", img)
    assert w[0] == 0x0C05 and w[4] == 0  # PDI SPI; DC SYNC out and latch in units on
    assert img[14] == crc8(img[:14]) and img[15] == 0
    assert struct.unpack_from("<IIII", img, 0x10) == (0x286, 8670, 0x00010000, 1)
    assert w[0x18:0x1C] == (0x1000, 128, 0x1080, 128)
    assert w[0x3F] == 1


def test_round_trip_matches_description() -> None:
    desc = default_description()
    p = parse_image(build_image(desc, serial=77, alias=0x1234))
    assert p.crc_ok
    assert (p.vendor_id, p.product_code, p.revision, p.serial) == (0x286, 8670, 0x10000, 77)
    assert p.words[4] == 0x1234
    assert p.name == "TMC8670" and p.strings[0] == "TMC8670"
    assert [(s[0], s[1], s[2], s[5]) for s in p.sms] == [
        (s.start, s.length, s.control, s.type_code) for s in desc.sync_managers
    ]
    rx = next(pd for pd in p.pdos if pd[0] == "RxPDO")
    assert [(e[0], e[4]) for e in rx[4]] == [(e.index, e.bits) for e in desc.rxpdos[0].entries]
    assert p.fmmus == [1, 2, 3]
    text = format_image(p)
    for s in ("0x00000286", "8670", "TMC8670", "STRINGS", "GENERAL", "FMMU", "SYNCM", "TXPDO",
              "RXPDO", "DC"):  # fmt: skip
        assert s in text


def test_build_is_deterministic_and_serials_differ() -> None:
    d = default_description()
    assert build_image(d) == build_image(d)
    assert build_image(d, serial=1) != build_image(d, serial=2)


def test_truncated_and_corrupt_images() -> None:
    img = bytearray(build_image(default_description()))
    with pytest.raises(SiiError, match="too short"):
        parse_image(bytes(img[:100]))
    with pytest.raises(SiiError, match="runs past the end"):
        parse_image(bytes(img[:0x90]))
    bad = bytearray(img)
    struct.pack_into("<H", bad, 0x82, 0x7FFF)  # strings category longer than the image
    with pytest.raises(SiiError, match="STRINGS at word 0x0040"):
        parse_image(bytes(bad))
    bad = bytearray(img)
    bad[14] ^= 1
    assert parse_image(bytes(bad)).crc_ok is False


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600))
def test_random_bytes_only_raise_sii_error(data: bytes) -> None:
    try:
        parse_image(data)
    except SiiError:
        pass


def test_description_errors_name_file_and_key() -> None:
    base = {"identity": {"vendor_id": 1, "product_code": 2, "revision": 3}}
    with pytest.raises(DescriptionError, match=r"x.yaml: sync_managers\[0\].control: expected"):
        parse_description({**base, "sync_managers": [{"start": 0, "length": 1, "control": "x"}]},
                          "x.yaml")  # fmt: skip
    with pytest.raises(DescriptionError, match=r"x\.yaml: colour: unknown key"):
        parse_description({**base, "colour": 1}, "x.yaml")


def test_store_save_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = tmp_path / "img.bin"
    EepromStore.save(p, b"\x01\x02" * 8)

    def boom(a: object, b: object) -> None:
        raise OSError("disk gone")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        EepromStore.save(p, b"\x03\x04" * 8)
    assert p.read_bytes() == b"\x01\x02" * 8
    assert [f.name for f in tmp_path.iterdir()] == ["img.bin"]


def test_store_rejects_bad_files(tmp_path: Path) -> None:
    p = tmp_path / "odd.bin"
    p.write_bytes(b"\x00" * 17)
    with pytest.raises(SiiError, match=r"odd\.bin"):
        EepromStore.load(p)
    with pytest.raises(SiiError, match="cannot read"):
        EepromStore.load(tmp_path / "missing.bin")
