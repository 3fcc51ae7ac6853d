"""The segment file's ``tmcl:``/``lin:`` keys become front doors hosted by the daemon."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from ecatsim.doors import from_config
from ecatsim.errors import UserError
from ecatsim.ethercat.segment_file import parse_segment
from tests.unit.test_doors import PipeDoor

SLAVES = [{"device": "echo"}]


def test_door_keys_are_kept_in_file_order_with_the_file_directory() -> None:
    cfg = parse_segment(
        {"slaves": SLAVES, "lin": {"pty": "lin0"}, "tmcl": {"listen": ["tcp://:0"]}},
        "seg.yaml",
        Path("/etc/ecatsim"),
    )
    assert cfg.doors == (("tmcl", {"listen": ["tcp://:0"]}), ("lin", {"pty": "lin0"}))
    assert cfg.base == Path("/etc/ecatsim")


def test_a_door_key_must_hold_a_mapping() -> None:
    with pytest.raises(UserError, match=r"^seg.yaml: tmcl: expected a mapping"):
        parse_segment({"slaves": SLAVES, "tmcl": ["tcp://:0"]}, "seg.yaml")


def test_an_unknown_top_level_key_names_the_allowed_ones() -> None:
    allowed = r"canbus: unknown key \(allowed: slaves, faults, tmcl, lin, eni, esi_dir, out_iface\)"
    with pytest.raises(UserError, match=allowed):
        parse_segment({"slaves": SLAVES, "canbus": {}}, "seg.yaml")


def test_no_doors_no_host() -> None:
    assert from_config.build_doors(parse_segment({"slaves": SLAVES}, "seg.yaml")) is None


def test_build_doors_hands_each_mapping_to_its_factory(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, dict[str, Any], str, Path | None]] = []

    def factory(key: str) -> from_config.DoorFactory:
        def make(data: dict[str, Any], src: str, base: Path | None) -> PipeDoor:
            seen.append((key, data, src, base))
            return PipeDoor()

        return make

    monkeypatch.setattr(from_config, "_factory", factory)
    cfg = parse_segment({"slaves": SLAVES, "lin": {"pty": "x"}}, "seg.yaml", Path("/d"))
    host = from_config.build_doors(cfg)
    assert host is not None
    try:
        assert list(host.doors) == ["lin"]
        assert seen == [("lin", {"pty": "x"}, "seg.yaml", Path("/d"))]
    finally:
        host.close()


def test_a_failing_door_closes_the_ones_built_before(monkeypatch: pytest.MonkeyPatch) -> None:
    first = PipeDoor()
    closed: list[bool] = []
    first.close = lambda: closed.append(True)  # type: ignore[method-assign]

    def factory(key: str) -> from_config.DoorFactory:
        def make(data: dict[str, Any], src: str, base: Path | None) -> PipeDoor:
            if key == "lin":
                raise UserError(f"{src}: lin.pty: expected a path")
            return first

        return make

    monkeypatch.setattr(from_config, "_factory", factory)
    cfg = parse_segment({"slaves": SLAVES, "tmcl": {}, "lin": {}}, "seg.yaml")
    with pytest.raises(UserError, match=r"lin\.pty"):
        from_config.build_doors(cfg)
    assert closed == [True]


def test_ctl_reaches_a_door_and_lists_it_in_status(tmp_path: Path) -> None:
    from ecatsim.clock import MonotonicClock
    from ecatsim.ctl.server import ControlSocket
    from ecatsim.doors.host import DoorHost
    from ecatsim.ethercat.assembly import build_segment
    from ecatsim.faults.engine import FaultEngine

    segment = build_segment(parse_segment({"slaves": SLAVES}, "seg.yaml"), MonotonicClock())
    door = PipeDoor()
    host = DoorHost({"tmcl": door})
    ctl = ControlSocket(tmp_path / "ctl", segment, FaultEngine(segment), host)
    try:
        assert ctl.handle({"cmd": "door", "door": "tmcl", "command": "x", "args": [1]}) == {
            "ok": True
        }
        assert ctl.handle({"cmd": "status"})["doors"] == {"tmcl": {"got": 0}}
        with pytest.raises(ValueError, match=r"no front door 'lin' \(serving: tmcl\)"):
            ctl.handle({"cmd": "door", "door": "lin", "command": "x"})
    finally:
        ctl.close()
        host.close()
