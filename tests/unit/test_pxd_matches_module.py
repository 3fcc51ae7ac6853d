"""Each ``.pxd`` of the compiled core declares exactly what its ``.py`` module holds.

The core is one source: every hot module is a ``.py`` file that Cython compiles with its
``.pxd`` beside it (docs/architecture.md, "The compiled core's dialect"). A field that is
in ``__slots__`` or assigned in a method but missing from the ``.pxd`` breaks only the
compiled build (an AttributeError at run time); a field or constant that the ``.pxd``
declares but the module no longer has is dead weight that hides the next mistake. These
tests read both files with :mod:`ast` and a small ``.pxd`` reader, so they hold for the
pure-Python and the compiled core alike.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "ecatsim"
PXDS = sorted(ROOT.rglob("*.pxd"))

_CLASS = re.compile(r"^cdef class (\w+)\s*(?:\(([\w.]+)\))?\s*:")
_FIELD = re.compile(r"^\s+cdef\s+(?:public\s+|readonly\s+)?(.+)$")
_MODULE_VAR = re.compile(r"^cdef\s+(?!class\b)(?!inline\b)([^()]+)$")


def _names(decl: str) -> list[str]:
    """Names declared by ``TYPE a, b, c`` (with ``unsigned char[:]``-style types)."""
    head, *rest = decl.split(",")
    names = [head.split()[-1]] + [r.strip() for r in rest]
    return [n.lstrip("*") for n in names if n]


def read_pxd(path: Path) -> tuple[dict[str, set[str]], set[str]]:
    """(fields per cdef class, module-level cdef variables) of one ``.pxd``."""
    classes: dict[str, set[str]] = {}
    module_vars: set[str] = set()
    current: str | None = None
    for raw in path.read_text().splitlines():
        line = raw.split("#", 1)[0].rstrip()
        if not line:
            continue
        m = _CLASS.match(line)
        if m:
            current = m.group(1)
            classes.setdefault(current, set())
            continue
        if not line.startswith((" ", "\t")):
            current = None
            mv = _MODULE_VAR.match(line)
            if mv and "(" not in line:
                module_vars.update(_names(mv.group(1)))
            continue
        f = _FIELD.match(line)
        if current is not None and f and "(" not in f.group(1):
            classes[current].update(_names(f.group(1)))
    return classes, module_vars


def _bases(path: Path) -> dict[str, str]:
    """Each cdef class of a ``.pxd`` with a base class: the base's (unqualified) name."""
    out: dict[str, str] = {}
    for raw in path.read_text().splitlines():
        m = _CLASS.match(raw)
        if m and m.group(2):
            out[m.group(1)] = m.group(2).split(".")[-1]
    return out


def _inherited(name: str) -> set[str]:
    """The fields a class's base classes (declared in any ``.pxd``) give it."""
    fields: dict[str, set[str]] = {}
    bases: dict[str, str] = {}
    for p in PXDS:
        fields.update(read_pxd(p)[0])
        bases.update(_bases(p))
    out: set[str] = set()
    base = bases.get(name)
    while base is not None and base in fields:
        out |= fields[base]
        base = bases.get(base)
    return out


def _module_of(pxd: Path) -> Path:
    for ext in (".py", ".pyx"):
        src = pxd.with_suffix(ext)
        if src.exists():
            return src
    raise AssertionError(f"{pxd} has no .py or .pyx beside it")


def _class_facts(cls: ast.ClassDef) -> tuple[set[str] | None, set[str]]:
    """(``__slots__`` names or None, attributes assigned as ``self.X`` in its methods)."""
    slots: set[str] | None = None
    assigned: set[str] = set()
    properties = {
        n.name
        for n in cls.body
        if isinstance(n, ast.FunctionDef)
        and any(
            (isinstance(d, ast.Name) and d.id == "property")
            or (isinstance(d, ast.Attribute) and d.attr == "setter")
            for d in n.decorator_list
        )
    }
    for node in cls.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__slots__" for t in node.targets
        ):
            value = ast.literal_eval(node.value)
            slots = set(value) if isinstance(value, tuple) else set()
        if isinstance(node, ast.FunctionDef):
            for sub in ast.walk(node):
                targets: list[ast.expr] = []
                if isinstance(sub, ast.Assign):
                    targets = list(sub.targets)
                elif isinstance(sub, ast.AnnAssign | ast.AugAssign):
                    targets = [sub.target]
                for t in targets:
                    if (
                        isinstance(t, ast.Attribute)
                        and isinstance(t.value, ast.Name)
                        and t.value.id == "self"
                    ):
                        assigned.add(t.attr)
    return slots, assigned - properties


def _module_names(tree: ast.Module) -> set[str]:
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            for t in node.targets:
                for n in ast.walk(t):
                    if isinstance(n, ast.Name):
                        names.add(n.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        elif isinstance(node, ast.ImportFrom | ast.Import):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, ast.FunctionDef | ast.ClassDef):
            names.add(node.name)
    return names


@pytest.mark.parametrize("pxd", PXDS, ids=[str(p.relative_to(ROOT)) for p in PXDS])
def test_pxd_fields_match_the_module(pxd: Path) -> None:
    classes, module_vars = read_pxd(pxd)
    src = _module_of(pxd)
    if src.suffix == ".pyx":
        pytest.skip("a .pyx holds its own declarations")  # pragma: no cover
    tree = ast.parse(src.read_text())
    defined = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
    for name, fields in classes.items():
        assert name in defined, f"{pxd.name}: cdef class {name} has no class in {src.name}"
        slots, assigned = _class_facts(defined[name])
        if slots is not None:
            assert fields == slots, (
                f"{src.name}:{name}: __slots__ and {pxd.name} differ: "
                f"only in __slots__ {sorted(slots - fields)}, only in .pxd {sorted(fields - slots)}"
            )
        missing = assigned - fields - _inherited(name)
        assert not missing, f"{src.name}:{name} assigns {sorted(missing)}, not in {pxd.name}"
    names = _module_names(tree)
    dead = module_vars - names
    assert not dead, f"{pxd.name} declares {sorted(dead)}, which {src.name} does not define"


def test_every_pxd_is_found() -> None:
    """The reader above sees the classes of the core (a guard against a reader that sees
    nothing and so passes everything)."""
    seen = {name for pxd in PXDS for name in read_pxd(pxd)[0]}
    assert {"Esc", "SyncManager", "FmmuMap", "DcUnit", "Segment", "Entry"} <= seen
    fields = read_pxd(ROOT / "esc" / "fmmu.pxd")[0]["FmmuMap"]
    assert {"lbit", "lend", "read", "aligned", "sm"} <= fields
