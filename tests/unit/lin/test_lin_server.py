"""The LIN front door: built from a segment file, hosted, controlled through ctl."""

from __future__ import annotations

import json
import os
import select
import tty
from pathlib import Path

import pytest

from ecatsim.ctl.server import ControlSocket
from ecatsim.doors.from_config import build_doors
from ecatsim.doors.host import DoorHost
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import parse_segment
from ecatsim.lin.frame import SLAVE_RESPONSE, frame, header
from ecatsim.lin.server import LinDoor, door_from_config
from ecatsim.lin.tables import State
from tests.support.linmaster import make_door, node_state


def test_segment_file_lin_key_builds_the_door(tmp_path: Path) -> None:
    seg = {"slaves": [{"device": "echo"}], "lin": {"pty": "lin0", "nodes": [{"name": "a"}]}}
    host = build_doors(parse_segment(seg, "seg.yaml", tmp_path))
    assert host is not None
    try:
        door = host.doors["lin"]
        assert isinstance(door, LinDoor)
        assert (tmp_path / "lin0").is_symlink()
        fd = os.open(tmp_path / "lin0", os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        os.write(fd, frame(0x3C, bytes((0x80, 0x81, 0x80, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))))
        os.write(fd, header(SLAVE_RESPONSE))
        got = b""
        while len(got) < 9 and select.select([host], [], [], 2)[0]:
            host.serve()
            while select.select([fd], [], [], 0.05)[0] and len(got) < 9:
                got += os.read(fd, 16)
        assert got[:8] == bytes((0x80, 0, 0, 0, 0x80, 0x02, 0, 0xFF))
        os.close(fd)
        assert [(n["name"], n["address"], n["state"], n["actpos"]) for n in
                host.status()["lin"]["nodes"]] == [("a", 0, "Stopped", 0)]  # fmt: skip
    finally:
        host.close()
    assert not (tmp_path / "lin0").exists()


def test_segment_lin_without_pty_is_one_line() -> None:
    with pytest.raises(UserError, match=r"^seg.yaml: lin.pty: missing: give the path"):
        door_from_config({"nodes": [{}]}, "seg.yaml", None)


def test_pty_path_taken_by_a_file(tmp_path: Path) -> None:
    (tmp_path / "lin0").write_text("x")
    with pytest.raises(UserError, match="exists and is not a symlink"):
        make_door(tmp_path)


def test_ctl_commands(tmp_path: Path) -> None:
    door, _clock, _m = make_door(tmp_path)
    try:
        assert "temp NODE CELSIUS" in door.ctl("help", [])["commands"]
        assert door.ctl("nodes", [])["nodes"][0]["state"] == "ShutDown"
        assert door.ctl("temp", ["node0", "150"])["node"]["flags"] == ["vddreset", "tw"]
        assert door.ctl("esw", ["0", "closed"])["node"]["esw"] == 1
        assert door.bus.nodes[0].motor.stops is None
        door.ctl("stops", ["0x00", "-10", "10"])
        assert door.bus.nodes[0].motor.stops == (-10.0, 10.0)
        door.ctl("power", ["node0"])
        assert door.bus.nodes[0].power_ons == 2
        for cmd, args, msg in [
            ("fly", ["node0"], "unknown lin command 'fly'"),
            ("temp", [], "which node?"),
            ("temp", ["nobody", "1"], "no node 'nobody'"),
            ("esw", ["node0", "ajar"], "lin esw NODE open|closed|auto"),
            ("ovc1", ["node0", "maybe"], "lin ovc1 NODE on|off"),
            ("stops", ["node0", "5", "1"], "above HIGH"),
        ]:
            with pytest.raises(ValueError, match=msg):
                door.ctl(cmd, args)
    finally:
        door.close()


def test_control_socket_for_a_doors_only_daemon(tmp_path: Path) -> None:
    door, _clock, _m = make_door(tmp_path)
    host = DoorHost({"lin": door})
    sock = ControlSocket(tmp_path / "ctl.sock", None, None, host)
    try:
        status = sock.answer(json.dumps({"cmd": "status"}).encode())
        assert status["ok"] and status["slaves"] == [] and "lin" in status["doors"]
        r = sock.answer(json.dumps({"cmd": "door", "door": "lin", "command": "cpfail",
                                    "args": ["node0", "on"]}).encode())  # fmt: skip
        assert r["ok"] and "cpfail" in r["node"]["flags"]
        r = sock.answer(json.dumps({"cmd": "peek", "slave": 0, "addr": 0, "len": 1}).encode())
        assert r == {"ok": False, "error": "'peek': this daemon serves front doors only "
                     "(use: status, door)"}  # fmt: skip
    finally:
        sock.close()
        host.close()


def test_node_sleeps_after_the_lin_timeout_and_wakes_on_a_header(tmp_path: Path) -> None:
    door, _clock, m = make_door(tmp_path, baud=9600)
    try:
        node = door.bus.nodes[0]
        assert door.bus.timeout_ns == 25000 * 1_000_000_000 // 9600  # 2.6 s at 9600 bit/s
        m.wait(2.5, keepalive=False)
        assert node_state(node) == State.SHUTDOWN
        m.wait(0.2, keepalive=False)
        assert node_state(node) == State.SLEEP
        assert m.read(0x3E) is None
        assert node_state(node) == State.SHUTDOWN and node.power_ons == 2
    finally:
        door.close()
