"""The LIN bus description: defaults, and one clear line per mistake (file, key, fix)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ecatsim.errors import UserError
from ecatsim.lin.config import BusConfig, NodeConfig, load_bus, parse_bus
from ecatsim.lin.otp import Otp

ROOT = Path(__file__).resolve().parents[3]


def test_defaults_one_node_address_zero() -> None:
    cfg = parse_bus({}, "bus.yaml")
    assert cfg == BusConfig((NodeConfig(name="node0"),), None, 19200, "bus.yaml")


def test_full_node(tmp_path: Path) -> None:
    cfg = parse_bus(
        {
            "pty": "lin0",
            "baud": 9600,
            "nodes": [
                {
                    "name": "a",
                    "hw": [1, 0, 1],
                    "otp": [0, 0, 3, 0, 0, 0, 0, 0],
                    "otp_file": "a.otp",
                    "rotor": 10,
                    "stops": [-5, 5.5],
                    "switch": [0, 1],
                }
            ],
        },
        "bus.yaml",
        tmp_path,
    )
    n = cfg.nodes[0]
    assert cfg.pty == tmp_path / "lin0" and cfg.baud == 9600
    assert (n.hw, n.otp[2], n.otp_file, n.rotor, n.stops, n.switch) == (
        0b101, 3, tmp_path / "a.otp", 10.0, (-5.0, 5.5), (0.0, 1.0)
    )  # fmt: skip


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"nodes": [{"hw": [0, 2, 0]}]},
            "bus.yaml: lin.nodes[0].hw: expected the pins [HW0, HW1, HW2]",
        ),
        ({"nodes": [{"otp": [0] * 7}]}, "bus.yaml: lin.nodes[0].otp: expected 8 bytes"),
        ({"nodes": [{"otp": [0] * 7 + [256]}]}, "bus.yaml: lin.nodes[0].otp: expected 8 bytes"),
        ({"nodes": [{"speed": 1}]}, "bus.yaml: lin.nodes[0].speed: unknown key"),
        ({"baud": 115200}, "bus.yaml: lin.baud: expected a LIN bit rate 1000..20000"),
        ({"nodes": []}, "bus.yaml: lin.nodes: expected a non-empty list"),
        (
            {"nodes": [{"name": "x"}, {"name": "x"}]},
            "bus.yaml: lin.nodes: node name 'x' appears twice",
        ),
        ({"nodes": [{"stops": [5, -5]}]}, "bus.yaml: lin.nodes[0].stops: low 5 is above high -5"),
        ({"nodes": [{"otp_file": "a"}, {"otp_file": "a"}]}, "bus.yaml: lin.nodes: two nodes share"),
        ({"port": 1}, "bus.yaml: lin.port: unknown key (allowed: pty, baud, nodes)"),
        ([], "bus.yaml: lin.: expected a mapping"),
    ],
)
def test_one_line_errors(data: object, message: str) -> None:
    with pytest.raises(UserError) as e:
        parse_bus(data, "bus.yaml", None, "lin.")
    assert str(e.value).startswith(message)
    assert "\n" not in str(e.value)


def test_load_bus_top_level_or_under_lin(tmp_path: Path) -> None:
    top = tmp_path / "top.yaml"
    top.write_text("nodes:\n  - {name: a}\n")
    seg = tmp_path / "seg.yaml"
    seg.write_text("slaves: [{device: echo}]\nlin:\n  nodes:\n    - {name: b, hw: [0, 0, 7]}\n")
    assert load_bus(top).nodes[0].name == "a"
    with pytest.raises(UserError, match=r"seg.yaml: lin.nodes\[0\].hw: expected"):
        load_bus(seg)
    with pytest.raises(UserError, match="cannot read the LIN bus file"):
        load_bus(tmp_path / "missing.yaml")


def test_shipped_example_has_two_nodes_at_addresses_1_and_2() -> None:
    cfg = load_bus(ROOT / "config" / "lin-bus.yaml")
    assert [(n.name, n.otp[2]) for n in cfg.nodes] == [("left", 1), ("right", 2)]


def test_otp_file_of_the_wrong_size(tmp_path: Path) -> None:
    f = tmp_path / "x.otp"
    f.write_bytes(b"\x00" * 7)
    with pytest.raises(UserError, match="holds exactly 8 bytes, this one 7"):
        Otp(bytes(8), f)


def test_otp_zap_is_one_way_locked_and_written_atomically(tmp_path: Path) -> None:
    f = tmp_path / "x.otp"
    o = Otp(bytes((0x11, 0, 0, 0, 0, 0, 0, 0x02)), f)  # LOCKBT: 0x00-0x01 protected
    assert not f.exists()
    assert o.zap(0, 0xFF) is False
    assert o.zap(3, 0x80) and o.zap(3, 0x01)
    assert o.zap(3, 0x00) is False
    assert f.read_bytes() == bytes((0x11, 0, 0, 0x81, 0, 0, 0, 0x02))
    assert o.zap(7, 0x01)  # LOCKBG
    assert o.zap(4, 0xFF) is False
    assert Otp(bytes(8), f).cells == bytearray((0x11, 0, 0, 0x81, 0, 0, 0, 0x03))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.otp"]  # no temp file left
