"""The LIN bus description: the pty, the bit rate and the TMC211 nodes on it.

The same mapping is the ``lin:`` key of a segment file and the whole of an
``ecatsim lin --config`` file (which may also hold it under ``lin:``)::

    pty: /tmp/lin0              # where the bus's pty is linked (--pty overrides)
    baud: 19200                 # bit rate: LIN timeout (25000 bits) and frame times
    nodes:                      # default: one node, HW0..2 = 0, OTP all zero
      - name: flap-left
        hw: [0, 0, 0]           # pins HW0, HW1, HW2 (TMC211 §6.5)
        otp: [0, 0, 0x01, 0, 0, 0, 0, 0]   # OTP bytes 0x00-0x07 (TMC211 §5.2.3)
        otp_file: left.otp      # the OTP cells persist here (zapping is one-way)
        rotor: 0                # where the rotor starts, 1/16 micro-steps
        stops: [-2000, 60000]   # mechanical stops the rotor cannot pass
        switch: [-2000, -1900]  # the rotor range where the switch on SWI is closed

Every problem is one line naming the file, the key and the fix.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from ecatsim.errors import UserError
from ecatsim.lin.otp import OTP_SIZE

MAX_NODES = 128  # seven address bits (TMC211 §6.5)
_BUS_KEYS = ("pty", "baud", "nodes")
_NODE_KEYS = ("name", "hw", "otp", "otp_file", "rotor", "stops", "switch")


@dataclass(frozen=True, slots=True)
class NodeConfig:
    """One TMC211 on the bus."""

    name: str = "node0"
    #: HW0 in bit 0, HW1 in bit 1, HW2 in bit 2
    hw: int = 0
    otp: bytes = bytes(OTP_SIZE)
    otp_file: Path | None = None
    rotor: float = 0.0
    stops: tuple[float, float] | None = None
    switch: tuple[float, float] | None = None


@dataclass(frozen=True, slots=True)
class BusConfig:
    """The bus and its nodes."""

    nodes: tuple[NodeConfig, ...] = (NodeConfig(),)
    pty: Path | None = None
    baud: int = 19200
    source: str = "<default>"


def _err(src: str, key: str, msg: str) -> UserError:
    return UserError(f"{src}: {key}: {msg}")


def _num(src: str, key: str, v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise _err(src, key, f"expected a number, got {v!r}")
    return float(v)


def _range(src: str, key: str, v: object) -> tuple[float, float]:
    if not isinstance(v, list) or len(v) != 2:
        raise _err(src, key, f"expected [low, high] in 1/16 micro-steps, got {v!r}")
    lo, hi = _num(src, key, v[0]), _num(src, key, v[1])
    if lo > hi:
        raise _err(src, key, f"low {lo:g} is above high {hi:g}: write [low, high]")
    return lo, hi


def _hw(src: str, key: str, v: object) -> int:
    if isinstance(v, list) and len(v) == 3 and all(b in (0, 1) and b is not True for b in v):
        return int(v[0]) | int(v[1]) << 1 | int(v[2]) << 2
    raise _err(src, key, f"expected the pins [HW0, HW1, HW2], each 0 or 1, got {v!r}")


def _otp(src: str, key: str, v: object) -> bytes:
    items: list[object] = list(v) if isinstance(v, list) else []
    cells = [b for b in items if type(b) is int and 0 <= b <= 255]
    if len(items) == OTP_SIZE and len(cells) == OTP_SIZE:
        return bytes(cells)
    raise _err(src, key, f"expected {OTP_SIZE} bytes 0..255 for OTP 0x00-0x07, got {v!r}")


def _path(src: str, base: Path | None, key: str, v: object) -> Path:
    if not isinstance(v, str) or not v:
        raise _err(src, key, f"expected a file path, got {v!r}")
    p = Path(v)
    return base / p if not p.is_absolute() and base is not None else p


def _node(src: str, base: Path | None, key: str, n: object, index: int) -> NodeConfig:
    if not isinstance(n, dict):
        raise _err(src, key, "expected a mapping like {name: flap, hw: [0, 0, 0]}")
    bad = sorted(set(n) - set(_NODE_KEYS))
    if bad:
        raise _err(src, f"{key}.{bad[0]}", f"unknown key (allowed: {', '.join(_NODE_KEYS)})")
    name = n.get("name", f"node{index}")
    if not isinstance(name, str) or not name:
        raise _err(src, f"{key}.name", f"expected a name, got {name!r}")
    return NodeConfig(
        name=name,
        hw=_hw(src, f"{key}.hw", n["hw"]) if "hw" in n else 0,
        otp=_otp(src, f"{key}.otp", n["otp"]) if "otp" in n else bytes(OTP_SIZE),
        otp_file=_path(src, base, f"{key}.otp_file", n["otp_file"]) if "otp_file" in n else None,
        rotor=_num(src, f"{key}.rotor", n.get("rotor", 0)),
        stops=_range(src, f"{key}.stops", n["stops"]) if "stops" in n else None,
        switch=_range(src, f"{key}.switch", n["switch"]) if "switch" in n else None,
    )


def parse_bus(data: object, src: str, base: Path | None = None, prefix: str = "") -> BusConfig:
    """Validate the bus mapping (``prefix`` names where it sits, e.g. ``lin.``)."""
    if not isinstance(data, dict):
        raise UserError(f"{src}: {prefix or 'top level'}: expected a mapping with a 'nodes:' list")
    bad = sorted(set(data) - set(_BUS_KEYS))
    if bad:
        raise _err(src, f"{prefix}{bad[0]}", f"unknown key (allowed: {', '.join(_BUS_KEYS)})")
    pty = _path(src, base, f"{prefix}pty", data["pty"]) if "pty" in data else None
    baud = data.get("baud", 19200)
    if isinstance(baud, bool) or not isinstance(baud, int) or not 1000 <= baud <= 20000:
        raise _err(src, f"{prefix}baud", f"expected a LIN bit rate 1000..20000, got {baud!r}")
    raw = data.get("nodes", [{}])
    if not isinstance(raw, list) or not raw:
        raise _err(src, f"{prefix}nodes", "expected a non-empty list of nodes")
    if len(raw) > MAX_NODES:
        raise _err(src, f"{prefix}nodes", f"at most {MAX_NODES} nodes (seven address bits)")
    nodes = tuple(_node(src, base, f"{prefix}nodes[{i}]", n, i) for i, n in enumerate(raw))
    names = [n.name for n in nodes]
    dup = next((x for x in names if names.count(x) > 1), None)
    if dup is not None:
        raise _err(src, f"{prefix}nodes", f"node name {dup!r} appears twice: names are unique")
    files = [n.otp_file for n in nodes if n.otp_file is not None]
    if len(set(files)) != len(files):
        raise _err(src, f"{prefix}nodes", "two nodes share an otp_file: give each its own")
    return BusConfig(nodes, pty, baud, src)


def load_bus(path: Path) -> BusConfig:
    """An ``ecatsim lin --config`` file: the bus mapping, at the top or under ``lin:``."""
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise UserError(f"{path}: cannot read the LIN bus file ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise UserError(f"{path}: not valid YAML ({getattr(exc, 'problem', exc)})") from exc
    if isinstance(data, dict) and "lin" in data:
        return parse_bus(data["lin"], str(path), path.parent, "lin.")
    return parse_bus(data, str(path), path.parent)
