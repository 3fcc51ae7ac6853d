"""Every path and module the design docs name exists in the tree.

docs/architecture.md, docs/performance.md and README.md state today's truth (issue 37):
a backticked ``ecatsim/...``, ``tests/...`` or ``tools/...`` path must be a file or a
directory of the repository, a ``bench/results/...`` file a stored run, and a dotted
``ecatsim.x.y`` name a module or package. A move or a rename that forgets the docs fails
here.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCS = ("docs/architecture.md", "docs/performance.md", "README.md")
BUILD_TEXT = (REPO / "setup.py").read_text() + (REPO / "pyproject.toml").read_text()

#: a path in backticks, up to the first space, backtick or ``::`` (a test's name)
_PATH = re.compile(r"`((?:ecatsim|tests|tools|bench/results)/[^`\s:]*)")
#: a dotted module name in backticks (``ecatsim.ctl.client``, ``ecatsim.esc.pdi.Pdi``)
_DOTTED = re.compile(r"`(ecatsim(?:\.\w+)+)")
#: a name standing for many: ``<N>``, ``*``, ``{a,b}``, ``...``
_PATTERN = re.compile(r"[<>*{}]|\.\.\.")


def _named(doc: str) -> tuple[set[str], set[str]]:
    text = (REPO / doc).read_text()
    paths = {m.rstrip(".,;)") for m in _PATH.findall(text) if not _PATTERN.search(m)}
    return paths, set(_DOTTED.findall(text))


def _source(dotted: str) -> Path | None:
    """The package directory or source file of module ``ecatsim.a.b``, if any."""
    base = REPO.joinpath(*dotted.split("."))
    if base.is_dir():
        return base
    for suffix in (".py", ".pyx"):
        if base.with_suffix(suffix).is_file():
            return base.with_suffix(suffix)
    return None


def _module_exists(dotted: str) -> bool:
    """``ecatsim.a.b`` is a package or a module, one the build makes (named in setup.py or
    pyproject.toml: ``ecatsim._cyutility``, ``ecatsim.defaults``), or ``ecatsim.a.B``
    names a class, function or constant that module ``ecatsim.a`` defines."""
    if _source(dotted) is not None or dotted in BUILD_TEXT:
        return True
    module, _, name = dotted.rpartition(".")
    src = _source(module)
    if src is None:
        return False
    if src.is_dir():
        src = src / "__init__.py"
    defined = rf"^\s*(?:class|def|cdef class|cpdef \w+|cdef \w+) {name}\b|^{name}\b"
    return src.is_file() and re.search(defined, src.read_text(), re.M) is not None


@pytest.mark.parametrize("doc", DOCS)
def test_every_path_named_exists(doc: str) -> None:
    paths, _ = _named(doc)
    assert paths, f"{doc} names no path: the pattern is wrong"
    missing = sorted(p for p in paths if not (REPO / p).exists())
    assert not missing, f"{doc} names paths that do not exist: {missing}"


@pytest.mark.parametrize("doc", DOCS)
def test_every_module_named_exists(doc: str) -> None:
    _, modules = _named(doc)
    missing = sorted(m for m in modules if not _module_exists(m))
    assert not missing, f"{doc} names modules that do not exist: {missing}"


def test_the_architecture_names_modules() -> None:
    """The check reads dotted names too (not only paths): the architecture names some."""
    _, modules = _named("docs/architecture.md")
    assert modules


def _table_names() -> set[str]:
    """The names in the first column of architecture.md's package table."""
    text = (REPO / "docs/architecture.md").read_text()
    section = text.split("## Packages and modules", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| `")]
    return {name for row in rows for name in re.findall(r"`([^`]+)`", row.split("|")[1])}


def test_the_table_names_every_package_and_top_level_module() -> None:
    """Issue 37: the map names the whole house, in one table without a break."""
    pkg = REPO / "ecatsim"
    expected = {f"ecatsim/{d.name}/" for d in pkg.iterdir() if (d / "__init__.py").is_file()}
    expected |= {
        f"ecatsim/{f.name}" for f in pkg.iterdir() if f.suffix in (".py", ".pyx") and f.is_file()
    }
    named = _table_names()
    assert not expected - named, f"architecture.md's table leaves out {sorted(expected - named)}"
    text = (REPO / "docs/architecture.md").read_text()
    table = text.split("## Packages and modules", 1)[1].split("\n## ", 1)[0]
    rows = [i for i, line in enumerate(table.splitlines()) if line.startswith("|")]
    assert rows == list(range(rows[0], rows[-1] + 1)), "a blank line breaks the table"


def test_every_result_cited_is_stored() -> None:
    """performance.md's table names its runs' JSON files by name: each is in bench/results
    (a bench run writes new ones there too, so the reverse is not asserted)."""
    text = (REPO / "docs/performance.md").read_text()
    cited = set(re.findall(r"`([\w-]+\.json)`", text))
    stored = {p.name for p in (REPO / "bench/results").iterdir() if p.suffix == ".json"}
    assert cited, "performance.md cites no run"
    assert not cited - stored, f"not in bench/results: {sorted(cited - stored)}"
