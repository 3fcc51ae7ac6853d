"""One source, three artefacts: the exported ESI, the SII image built from it, and the OD.

Ref: ETG.2000 (ESI), ETG.2010 (SII).
"""

from __future__ import annotations

from pathlib import Path

import lxml.etree as ET
import pytest
from click.testing import CliRunner

from ecatsim.cli import cli
from ecatsim.device.description import default_description
from ecatsim.sii.image import build_image, parse_image
from ecatsim.slave.od_build import build_od


def run(*args: str) -> tuple[int, str]:
    r = CliRunner().invoke(cli, list(args))
    return r.exit_code, r.output


def test_export_is_well_formed_and_carries_every_object(tmp_path: Path) -> None:
    out = tmp_path / "tmc8670.xml"
    assert run("esi", "export", "-o", str(out))[0] == 0
    root = ET.parse(str(out)).getroot()
    dev = root.find("Descriptions/Devices/Device")
    assert dev is not None
    assert dev.find("Type").get("ProductCode") == "#x000021DE"
    desc = default_description()
    od = build_od(desc)
    exported = {
        int(o.findtext("Index")[2:], 16) for o in dev.findall("Profile/Dictionary/Objects/Object")
    }
    assert exported == set(od.objects)
    coe = dev.find("Mailbox/CoE")
    assert coe is not None and coe.get("SdoInfo") == "true" and coe.get("CompleteAccess") == "true"
    assert dev.find("Mailbox/FoE") is not None
    assert [s.text for s in dev.findall("Sm")] == ["MBoxOut", "MBoxIn", "Outputs", "Inputs"]
    assert [o.findtext("AssignActivate") for o in dev.findall("Dc/OpMode")] == ["#x0000", "#x0300"]


def test_eeprom_build_of_export_reproduces_the_embedded_image(tmp_path: Path) -> None:
    xml = tmp_path / "d.xml"
    img = tmp_path / "d.bin"
    assert run("esi", "export", "-o", str(xml))[0] == 0
    code, out = run("eeprom", "build", str(xml), "-o", str(img), "--serial", "1")
    assert code == 0, out
    assert img.read_bytes() == build_image(default_description())
    code, out = run("eeprom", "show", str(img))
    assert code == 0
    assert "0x00000286" in out and "TMC8670" in out and "checksum           0x" in out
    assert parse_image(img.read_bytes()).crc_ok


def test_bad_esi_gives_one_line_and_no_output(tmp_path: Path) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text("<EtherCATInfo><Vendor><Id>#x2</Id></Vendor><Descriptions><Devices>")
    out = tmp_path / "o.bin"
    r = CliRunner().invoke(cli, ["eeprom", "build", str(bad), "-o", str(out)])
    assert r.exit_code != 0
    assert "not a readable XML file" in str(r.exception)
    assert not out.exists()
    bad.write_text(
        "<EtherCATInfo><Vendor><Id>#x2</Id></Vendor><Descriptions><Devices>"
        '<Device><Type ProductCode="#x1" RevisionNo="1">A</Type><Name>A</Name></Device>'
        '<Device><Type ProductCode="#x1" RevisionNo="2">A</Type><Name>A2</Name></Device>'
        "</Devices></Descriptions></EtherCATInfo>"
    )
    r = CliRunner().invoke(cli, ["eeprom", "build", str(bad), "-o", str(out)])
    assert "pick one with --product/--revision" in str(r.exception)
    assert not out.exists()
    r = CliRunner().invoke(cli, ["eeprom", "build", str(bad), "-o", str(out), "--revision", "2"])
    assert r.exit_code == 0, r.output
    assert parse_image(out.read_bytes()).string(1) == "A2"


@pytest.mark.parametrize("word", [0x08, 0x0A, 0x0C])
def test_sii_identity_equals_1018(word: int) -> None:
    desc = default_description()
    img = build_image(desc, serial=7)
    od = build_od(desc)
    sub = {0x08: 1, 0x0A: 2, 0x0C: 3}[word]
    assert img[word * 2 : word * 2 + 4] == od.read(0x1018, sub)
    assert img[0x0E * 2 : 0x0E * 2 + 4] == (7).to_bytes(4, "little")  # the serial: SII only


def test_sii_mailbox_words_match_the_sms() -> None:
    desc = default_description()
    p = parse_image(build_image(desc))
    sm0, sm1 = desc.sync_managers[0], desc.sync_managers[1]
    assert p.mailbox[4:8] == (sm0.start, sm0.length, sm1.start, sm1.length)
    assert p.protocols == 0x04 | 0x08  # CoE, FoE


def test_segment_yaml_loads_a_user_esi(tmp_path: Path) -> None:
    from ecatsim.clock import ManualClock
    from ecatsim.ethercat.assembly import build_segment
    from ecatsim.ethercat.segment_file import load_segment

    xml = tmp_path / "d.xml"
    assert run("esi", "export", "-o", str(xml))[0] == 0
    text = xml.read_text().replace("<Name>TMC8670</Name>", "<Name>My drive</Name>", 1)
    xml.write_text(text)
    seg_yaml = tmp_path / "seg.yaml"
    seg_yaml.write_text(f"slaves:\n  - device: tmc8670\n    esi: {xml.name}\n")
    seg = build_segment(load_segment(seg_yaml), ManualClock())
    p = parse_image(bytes(seg.escs[0].eeprom.image))
    assert p.name == "My drive" and p.product_code == 8670
