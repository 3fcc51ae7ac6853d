"""The firmware and devices reach the ESC only through its PDI face.

Two faces, one seam: docs/architecture.md.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import ecatsim

ROOT = Path(ecatsim.__file__).parent
#: the PDI face: esc/pdi.py (and its declarations esc/pdi.pxd for the compiled firmware)
ALLOWED_ESC = {"ecatsim.esc.pdi"}


CIMPORT = re.compile(r"^\s*(?:from\s+([\w.]+)\s+cimport|cimport\s+([\w.]+))", re.M)
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
#: C sources and headers, Cython declarations and sources
NATIVE = ("*.c", "*.h", "*.pxd", "*.pyx")


def _imports(path: Path, root: Path = ROOT) -> set[str]:
    """The modules a .py imports or cimports (Cython's pure-Python ``cython.cimports.X``
    counts as X), a .pxd/.pyx cimports, or a C file includes (as a dotted module path of
    the header, relative to the package: ``ecatsim.esc._sm``)."""
    text = path.read_text()
    out: set[str] = set()
    if path.suffix in (".c", ".h"):
        for inc in INCLUDE.findall(text):
            target = (path.parent / inc).resolve()
            if target.is_relative_to(root):
                rel = target.relative_to(root).with_suffix("")
                out.add(".".join(("ecatsim", *rel.parts)))
        return out
    if path.suffix in (".pxd", ".pyx"):
        for a, b in CIMPORT.findall(text):
            out.add(a or b)
        return out
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return {m.removeprefix("cython.cimports.") for m in out}


def _sources(pkg: str) -> list[Path]:
    return sorted(f for pat in ("*.py", *NATIVE) for f in (ROOT / pkg).rglob(pat))


def test_slave_and_device_use_only_the_pdi_face() -> None:
    offenders = []
    for pkg in ("slave", "device", "pdi_spi", "mfcio"):
        for f in _sources(pkg):
            for mod in _imports(f):
                is_esc = mod == "ecatsim.esc" or mod.startswith("ecatsim.esc.")
                if is_esc and not any(mod == a or mod.startswith(a + ".") for a in ALLOWED_ESC):
                    offenders.append(f"{f.relative_to(ROOT)} imports {mod}")
    assert offenders == []


def test_esc_does_not_import_firmware_or_devices() -> None:
    offenders = []
    for f in _sources("esc"):
        for mod in _imports(f):
            if mod.startswith(("ecatsim.slave", "ecatsim.device", "ecatsim.mfcio")):
                offenders.append(f"{f.relative_to(ROOT)} imports {mod}")
    assert offenders == []


def test_layering_check_detects_a_violation(tmp_path: Path) -> None:
    f = tmp_path / "x.py"
    f.write_text("from ecatsim.esc.core import Esc\nfrom cython.cimports.ecatsim.esc import sm\n")
    assert {"ecatsim.esc.core", "ecatsim.esc"} <= _imports(f)
    f = tmp_path / "x.pxd"
    f.write_text("from ecatsim.esc.sm cimport SyncManager\ncimport ecatsim.esc.dc\n")
    assert _imports(f) == {"ecatsim.esc.sm", "ecatsim.esc.dc"}
    f = tmp_path / "slave" / "x.h"
    f.parent.mkdir()
    f.write_text('#include "../esc/_sm.h"\n#include <Python.h>\n')
    assert _imports(f, tmp_path.resolve()) == {"ecatsim.esc._sm"}
