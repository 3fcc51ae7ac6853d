"""Every register constant a compiled ESC module takes from ``esc/regs.py`` is a C constant.

``regs.py`` is the one source of the register addresses and bits (tied to the register
table by test_regs_match_table.py). A compiled module imports the names it uses from it,
and its ``.pxd`` declares them ``cdef long long`` so that Cython makes them C constants,
set once from ``regs.py`` at import. A name the ``.pxd`` does not declare still works but
is a Python global looked up at every use, a slowdown no other test sees (names a module
re-exports, its ``__all__``, stay Python attributes, as they must); a name the
``.pxd`` declares that the module no longer imports is caught by
tests/unit/test_pxd_matches_module.py. Ref: docs/architecture.md (the compiled core).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.unit.test_pxd_matches_module import read_pxd

ESC = Path(__file__).resolve().parents[3] / "ecatsim" / "esc"
COMPILED = sorted(p.with_suffix(".py") for p in ESC.glob("*.pxd"))


def _from_regs(src: Path) -> set[str]:
    """The names ``src`` imports with ``from ecatsim.esc.regs import ...``, but those it
    re-exports (its ``__all__``: Python attributes of the module, as they must be)."""
    out: set[str] = set()
    exported: set[str] = set()
    for node in ast.parse(src.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.module == "ecatsim.esc.regs":
            out.update(a.asname or a.name for a in node.names)
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            exported.update(ast.literal_eval(node.value))
    return out - exported


@pytest.mark.parametrize("src", COMPILED, ids=[p.name for p in COMPILED])
def test_the_register_names_a_compiled_module_uses_are_c_constants(src: Path) -> None:
    _classes, declared = read_pxd(src.with_suffix(".pxd"))
    missing = _from_regs(src) - declared
    assert not missing, (
        f"{src.name} imports {sorted(missing)} from regs.py; declare them in the .pxd"
    )


def test_the_reader_sees_the_imports() -> None:
    """A guard against a reader that finds nothing and so passes everything."""
    assert {"DC_SYSTEM_TIME", "AL_STATUS"} <= _from_regs(ESC / "core.py")
    assert "DC_SYSTEM_TIME" in _from_regs(ESC / "dc.py")
