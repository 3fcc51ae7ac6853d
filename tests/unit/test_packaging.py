"""Every package of the source tree is in the wheel (a non-editable install, as in the
container image, must not lose one)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_subpackage_is_listed() -> None:
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(conf["tool"]["setuptools"]["packages"])
    found = {
        ".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "ecatsim").rglob("__init__.py")
    }
    assert found - listed == set()


def test_no_module_is_over_1000_lines() -> None:
    """One module per unit (docs/architecture.md): none of the package grows past 1000
    lines."""
    root = Path(__file__).resolve().parents[2] / "ecatsim"
    sizes = {
        str(f.relative_to(root)): len(f.read_text().splitlines())
        for f in [*root.rglob("*.py"), *root.rglob("*.pyx")]
    }
    assert {f: n for f, n in sizes.items() if n > 1000} == {}
