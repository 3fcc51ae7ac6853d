"""The firmware and devices reach the ESC only through its PDI face.

Two faces, one seam: docs/architecture.md.
"""

from __future__ import annotations

import ast
from pathlib import Path

import ecatsim

ROOT = Path(ecatsim.__file__).parent
ALLOWED_ESC = {"ecatsim.esc.pdi"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def test_slave_and_device_use_only_the_pdi_face() -> None:
    offenders = []
    for pkg in ("slave", "device", "pdi_spi", "mfcio"):
        for f in sorted((ROOT / pkg).rglob("*.py")):
            for mod in _imports(f):
                is_esc = mod == "ecatsim.esc" or mod.startswith("ecatsim.esc.")
                if is_esc and not any(mod == a or mod.startswith(a + ".") for a in ALLOWED_ESC):
                    offenders.append(f"{f.relative_to(ROOT)} imports {mod}")
    assert offenders == []


def test_esc_does_not_import_firmware_or_devices() -> None:
    offenders = []
    for f in sorted((ROOT / "esc").rglob("*.py")):
        for mod in _imports(f):
            if mod.startswith(("ecatsim.slave", "ecatsim.device", "ecatsim.mfcio")):
                offenders.append(f"{f.relative_to(ROOT)} imports {mod}")
    assert offenders == []


def test_layering_check_detects_a_violation(tmp_path: Path) -> None:
    f = tmp_path / "x.py"
    f.write_text("from ecatsim.esc.core import Esc\n")
    assert "ecatsim.esc.core" in _imports(f)
