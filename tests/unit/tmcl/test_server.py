"""The ``tmcl:`` key of a segment file, the control socket's view, the EEPROM file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ecatsim.ctl.server import ControlSocket
from ecatsim.doors.from_config import build_doors
from ecatsim.doors.host import DoorHost
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import parse_segment
from ecatsim.tmcl.server import TmclDoor, door_from_config


def test_segment_file_tmcl_key_builds_a_door(tmp_path: Path) -> None:
    cfg = parse_segment(
        {
            "slaves": [{"device": "echo"}],
            "tmcl": {
                "listen": ["tcp://127.0.0.1:0", "pty:tmcm"],
                "eeprom": "tmcl.json",
                "modules": [
                    {"address": 1, "switches": {"home": 25600}},
                    {"address": 2, "motor": {"load_inertia": 1e-4}, "analog": [302, 0]},
                ],
            },
        },
        "seg.yaml",
        tmp_path,
    )
    host = build_doors(cfg)
    assert host is not None
    try:
        door = host.doors["tmcl"]
        assert isinstance(door, TmclDoor)
        assert [m.address for m in door.modules] == [1, 2]
        assert door.eeprom.path == tmp_path / "tmcl.json"
        assert (tmp_path / "tmcm").is_symlink()
        assert door.modules[1].cfg.mech.load_inertia == 1e-4
        status = host.status()["tmcl"]
        assert status["listen"][1] == f"pty:{tmp_path / 'tmcm'}"
        assert [m["address"] for m in status["modules"]] == [1, 2]
    finally:
        host.close()
    assert not (tmp_path / "tmcm").exists()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({}, r"^seg.yaml: tmcl.listen: expected one or more URLs"),
        ({"listen": ["udp://x:1"]}, r"tmcl.listen: 'udp://x:1': expected tcp://HOST:PORT"),
        ({"listen": "tcp://h:1", "port": 1}, r"tmcl.port: unknown key"),
        ({"listen": "tcp://h:1", "modules": [{"address": 300}]}, r"modules\[0\].address"),
        (
            {"listen": "tcp://h:1", "modules": [{"address": 1}, {"address": 1}]},
            r"modules\[1\].address: 1 is used twice",
        ),
        ({"listen": "tcp://h:1", "modules": [{"motor": {"mass": 1}}]}, r"motor.mass: unknown"),
        (
            {"listen": "tcp://h:1", "modules": [{"motor": {"supply_v": 0}}]},
            r"modules\[0\].motor.supply_v: expected a number above 0, got 0$",
        ),
        (
            {"listen": "tcp://h:1", "modules": [{"motor": {"inductance": -1e-3}}]},
            r"motor.inductance: expected 0 or more",
        ),
        ({"listen": "tcp://h:1", "modules": [{"analog": [5000, 0]}]}, r"analog: expected two"),
    ],
)
def test_bad_config_is_one_line_naming_file_key_and_fix(
    data: dict[str, object], message: str
) -> None:
    with pytest.raises(UserError, match=message):
        door_from_config(data, "seg.yaml", None)


def test_ctl_status_and_door_commands_without_a_segment(tmp_path: Path) -> None:
    door = door_from_config({"listen": ["tcp://127.0.0.1:0"]}, "seg.yaml", None)
    host = DoorHost({"tmcl": door})
    ctl = ControlSocket(tmp_path / "ctl.sock", None, None, host)
    try:
        st = ctl.handle({"cmd": "status"})
        assert st["slaves"] == []
        assert st["doors"]["tmcl"]["modules"][0]["address"] == 1
        r = ctl.handle(
            {
                "cmd": "door",
                "door": "tmcl",
                "command": "fault",
                "args": ["1", "overtemperature", "on"],
            }
        )
        assert r == {"ok": True, "faults": ["overtemperature"]}
        assert (
            ctl.handle({"cmd": "door", "door": "tmcl", "command": "gap", "args": ["1", "208"]})[
                "value"
            ]
            & 0b110
            == 0b110
        )
        assert (
            ctl.handle({"cmd": "door", "door": "tmcl", "command": "gap", "args": ["1", "18"]})[
                "value"
            ]
            & 2048
        )
        assert ctl.handle(
            {"cmd": "door", "door": "tmcl", "command": "switch", "args": ["1", "left", "on"]}
        ) == {"ok": True, "left": True}
        assert (
            ctl.handle({"cmd": "door", "door": "tmcl", "command": "ggp", "args": ["1", "66", "0"]})[
                "value"
            ]
            == 1
        )
        bad = ctl.answer(
            json.dumps(
                {"cmd": "door", "door": "tmcl", "command": "gap", "args": ["7", "1"]}
            ).encode()
        )
        assert bad == {"ok": False, "error": "no TMCL module at address 7 (modules at: 1)"}
        bad = ctl.answer(json.dumps({"cmd": "door", "door": "tmcl", "command": "load"}).encode())
        assert bad["error"].startswith("usage: load ADDR NM")
        bad = ctl.answer(json.dumps({"cmd": "peek", "slave": 0, "addr": 0, "len": 1}).encode())
        assert bad == {
            "ok": False,
            "error": "'peek': this daemon serves front doors only (use: status, door)",
        }
    finally:
        ctl.close()
        host.close()


def test_eeprom_file_is_checked(tmp_path: Path) -> None:
    bad = tmp_path / "e.json"
    bad.write_text("[1, 2]")
    with pytest.raises(UserError, match=r"--eeprom .*e.json: format is not"):
        door_from_config({"listen": ["tcp://127.0.0.1:0"], "eeprom": str(bad)}, "s.yaml", None)
    bad.write_text("{")
    with pytest.raises(UserError, match=r"not a TMCL EEPROM file"):
        door_from_config({"listen": ["tcp://127.0.0.1:0"], "eeprom": str(bad)}, "s.yaml", None)
