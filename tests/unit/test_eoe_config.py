"""A slave's ``eoe:`` entry: parsing and its one-line errors, the SII word and ESI that
declare EoE, and the EoE line of ``ctl status``. Ref: ETG.1000.6 §5.7; ETG.2010 Table 2;
ETG.2000 (Mailbox/EoE)."""

from __future__ import annotations

from pathlib import Path

import lxml.etree as ET
import pytest
from click.testing import CliRunner

from ecatsim.cli import cli
from ecatsim.ctl.table import eoe_text
from ecatsim.device.esi import read_esi
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import EoeConfig, parse_segment
from ecatsim.sii.image import parse_image


def test_eoe_entry_parses_address_mask_and_mac() -> None:
    cfg = parse_segment(
        {"slaves": [{"device": "tmc8670", "eoe": {"tap": "eoe0", "ip": "10.77.0.2/24",
                                                  "mac": "02:00:00:00:00:2a"}}]},
        "seg.yaml",
    )  # fmt: skip
    assert cfg.slaves[0].eoe == EoeConfig(
        "eoe0", bytes([10, 77, 0, 2]), bytes([255, 255, 255, 0]), bytes.fromhex("02000000002a")
    )
    assert parse_segment({"slaves": [{"eoe": {"tap": "e1"}}]}, "s").slaves[0].eoe == EoeConfig("e1")


@pytest.mark.parametrize(
    ("slave", "where"),
    [
        ({"eoe": "eoe0"}, "slaves[0].eoe: expected a mapping"),
        ({"eoe": {"tap": "x" * 16}}, "slaves[0].eoe.tap: expected an interface name"),
        ({"eoe": {"tap": "e", "ip": "10.77.0.2"}}, "slaves[0].eoe.ip: expected an address"),
        ({"eoe": {"tap": "e", "ip": "10.77.0.256/24"}}, "slaves[0].eoe.ip: expected"),
        ({"eoe": {"tap": "e", "ip": "10.77.0.2/33"}}, "slaves[0].eoe.ip: expected"),
        (
            {"eoe": {"tap": "e", "mac": "01:00:5e:00:00:01"}},
            "slaves[0].eoe.mac: expected a unicast",
        ),
        ({"eoe": {"tap": "e", "mac": "02:00:00:00:00"}}, "slaves[0].eoe.mac: expected"),
        ({"eoe": {"tap": "e", "dhcp": True}}, "slaves[0].eoe.dhcp: unknown key"),
        ({"count": 2, "eoe": {"tap": "e"}}, "slaves[0].eoe: one TAP device serves one slave"),
        ({"device": "echo", "eoe": {"tap": "e"}}, "slaves[0].eoe: one TAP device"),
    ],
)
def test_bad_eoe_entries_give_one_line(slave: dict[str, object], where: str) -> None:
    with pytest.raises(UserError) as e:
        parse_segment({"slaves": [slave]}, "seg.yaml")
    msg = str(e.value)
    assert msg.startswith("seg.yaml: " + where) and "\n" not in msg


def test_one_tap_name_twice_is_refused() -> None:
    with pytest.raises(UserError, match=r"slaves\[0\].eoe.tap: e0 is named twice"):
        parse_segment({"slaves": [{"eoe": {"tap": "e0"}}, {"eoe": {"tap": "e0"}}]}, "seg.yaml")


def test_esi_export_declares_eoe_and_the_sii_built_from_it_too(tmp_path: Path) -> None:
    xml, img = tmp_path / "d.xml", tmp_path / "d.bin"
    r = CliRunner().invoke(cli, ["esi", "export", "-o", str(xml), "--eoe"])
    assert r.exit_code == 0, r.output
    mbx = ET.parse(str(xml)).getroot().find("Descriptions/Devices/Device/Mailbox")
    assert mbx is not None
    assert [c.tag for c in mbx] == ["EoE", "CoE", "FoE"]
    assert mbx.find("EoE").get("IP") == "true"
    assert "eoe" in read_esi(xml).mailbox.protocols
    r = CliRunner().invoke(cli, ["eeprom", "build", str(xml), "-o", str(img)])
    assert r.exit_code == 0, r.output
    assert parse_image(img.read_bytes()).protocols == 0x02 | 0x04 | 0x08  # EoE, CoE, FoE
    # without --eoe: no EoE
    r = CliRunner().invoke(cli, ["esi", "export", "-o", str(xml)])
    mbx = ET.parse(str(xml)).getroot().find("Descriptions/Devices/Device/Mailbox")
    assert mbx is not None and mbx.find("EoE") is None


def test_ctl_status_eoe_line() -> None:
    e = {
        "ip": "10.77.0.2",
        "to_slave_frames": 25,
        "to_slave_fragments": 95,
        "to_slave_dropped": 1,
        "to_master_frames": 24,
        "to_master_fragments": 94,
        "to_master_dropped": 0,
        "requests": 2,
        "refused": 0,
    }
    assert eoe_text(1, e) == (
        "slave 1 EoE ip 10.77.0.2: to slave 25 frames (95 fragments, 1 dropped), "
        "to master 24 frames (94 fragments, 0 dropped), 2 requests (0 refused)"
    )
