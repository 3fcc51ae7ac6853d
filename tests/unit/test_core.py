"""Which core runs: the compiled one, built by Cython from the same .py files, or those
files themselves (decisions P2, P8). ``ecatsim --version`` says which; the compiled core
must engage wherever it was built. Ref: ecatsim/compiled.py."""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import runpy
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from ecatsim import compiled

PURE = os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0")


def run(*args: str, **env: str) -> list[str]:
    full = {k: v for k, v in os.environ.items() if k != "ECATSIM_PURE_PYTHON"}
    full.update(env)
    out = subprocess.run(
        [sys.executable, *args], env=full, capture_output=True, text=True, check=True
    )
    return out.stdout.splitlines()


def built(name: str) -> bool:
    """A compiled module for this interpreter sits beside the module's .py."""
    src = Path(compiled.__file__).parent.joinpath(*name.split(".")[1:])
    return any(
        src.with_name(src.name + suffix).is_file()
        for suffix in importlib.machinery.EXTENSION_SUFFIXES
    )


VERSION = ["-c", "from ecatsim.cli import cli; cli(['--version'])"]


def test_version_names_the_pure_python_core_and_why() -> None:
    assert run(*VERSION, ECATSIM_PURE_PYTHON="1") == [
        "ecatsim, version 0.1.0",
        "core: pure-python (ECATSIM_PURE_PYTHON is set)",
    ]


def test_pure_python_imports_every_core_module_from_its_source() -> None:
    probe = (
        "import importlib; from ecatsim import compiled\n"
        "print(*(importlib.import_module(n).__file__.endswith('.py') for n in compiled.CORE))"
    )
    assert run("-c", probe, ECATSIM_PURE_PYTHON="1") == [" ".join(["True"] * len(compiled.CORE))]


@pytest.mark.skipif(PURE, reason="this run is the pure-Python core's (ECATSIM_PURE_PYTHON)")
def test_the_compiled_core_engages_where_it_was_built() -> None:
    """Every module built for this interpreter is the one imported, and ``--version`` says
    ``core: compiled``. Under CI the core must have been built (on 3.11, 3.12, 3.13)."""
    missing = [n for n in compiled.CORE if not built(n)]
    if missing and not os.environ.get("CI"):
        pytest.skip(f"not built here: {missing}")
    assert missing == []
    assert [n for n in compiled.CORE if not compiled.is_compiled(importlib.import_module(n))] == []
    assert compiled.core_status() == (True, "")
    assert run(*VERSION)[1] == "core: compiled"


def test_a_free_threaded_interpreter_runs_the_pure_python_core(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("ECATSIM_PURE_PYTHON", raising=False)
    monkeypatch.setattr(compiled, "free_threaded", lambda: True)
    assert compiled.core_status() == (
        False,
        "free-threaded interpreter: the compiled core needs the GIL",
    )


def _touch(path: Path, mtime: int) -> None:
    path.write_text("")
    os.utime(path, (mtime, mtime))


def test_a_stale_compiled_module_is_not_used(tmp_path: Path) -> None:
    """In a source checkout a compiled module older than its .py (edited since the last
    install) is passed over for the .py; a current one is imported as usual."""
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    _touch(tmp_path / "servo.py", 2_000_000_000)
    _touch(tmp_path / f"servo{suffix}", 1_000_000_000)
    _touch(tmp_path / "drive.py", 1_000_000_000)
    _touch(tmp_path / f"drive{suffix}", 2_000_000_000)
    _touch(tmp_path / "cli.py", 2_000_000_000)
    _touch(tmp_path / f"cli{suffix}", 1_000_000_000)
    assert {"ecatsim.device.servo", "ecatsim.device.drive"} <= set(compiled.CORE)
    finder = compiled.PreferSource(always=False)
    before = list(compiled.stale)
    try:
        spec = finder.find_spec("ecatsim.device.servo", [str(tmp_path)])
        assert spec is not None and spec.origin == str(tmp_path / "servo.py")
        assert compiled.stale[len(before) :] == ["ecatsim.device.servo"]
        assert finder.find_spec("ecatsim.device.drive", [str(tmp_path)]) is None
        assert finder.find_spec("ecatsim.cli", [str(tmp_path)]) is None  # not in the core
        always = compiled.PreferSource(always=True)
        spec = always.find_spec("ecatsim.device.drive", [str(tmp_path)])
        assert spec is not None and spec.origin == str(tmp_path / "drive.py")
    finally:
        compiled.stale[:] = before


def test_setup_py_builds_the_core_list() -> None:
    """setup.py reads CORE from ecatsim/compiled.py as text: both name the same modules."""
    setup = runpy.run_path(str(Path(compiled.__file__).parents[1] / "setup.py"), run_name="probe")
    assert tuple(setup["core_modules"]()) == compiled.CORE


def _cythonize_calls(monkeypatch: pytest.MonkeyPatch) -> tuple[list[Any], dict[str, Any]]:
    """setup.py's extensions as cythonize would get them (Cython replaced by a recorder),
    and the options it was called with."""
    setuptools = pytest.importorskip("setuptools")
    build = pytest.importorskip("Cython.Build")
    seen: dict[str, Any] = {}

    def fake_cythonize(exts: list[Any], **kw: Any) -> list[Any]:
        seen.update(kw)
        return [setuptools.Extension(e.name, [e.sources[0].rsplit(".", 1)[0] + ".c"]) for e in exts]

    monkeypatch.setattr(build, "cythonize", fake_cythonize)
    setup = runpy.run_path(str(Path(compiled.__file__).parents[1] / "setup.py"), run_name="probe")
    return setup["core"](), seen


def test_every_extension_is_optional(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where no C compiler exists pip still installs ecatsim, and the pure-Python core runs:
    every extension setup.py declares is optional, including those cythonize makes anew.
    They are all Cython modules: no hand-written C is left. The C files in the package are
    the benchmark's floor, its host probe and its stall watch, separate programs the bench
    compiles at run time (decisions B2, B7, B8), never linked into ecatsim."""
    exts, _ = _cythonize_calls(monkeypatch)
    assert {e.name for e in exts} == {
        *compiled.CORE,
        "ecatsim.ethercat.responder",
        "ecatsim._cyutility",
    }
    assert [e.name for e in exts if not e.optional] == []
    root = Path(compiled.__file__).parent
    found = sorted(p.relative_to(root).as_posix() for p in root.rglob("*.[ch]"))
    assert found == ["bench/echo.c", "bench/stallwatch.c", "bench/steadiness.c"]


def test_every_extension_declares_that_it_needs_the_gil(monkeypatch: pytest.MonkeyPatch) -> None:
    """Cython declares Py_mod_gil as Py_MOD_GIL_USED for modules not marked free-threading
    compatible: on a free-threaded interpreter the loader does not import them (the
    pure-Python core runs, ecatsim/compiled.py), and an import would not turn the GIL on
    silently."""
    _, seen = _cythonize_calls(monkeypatch)
    assert seen["compiler_directives"]["freethreading_compatible"] is False
    # Cython's run-time code is one shared module, built with the same directives
    assert seen["shared_utility_qualified_name"] == "ecatsim._cyutility"
