"""Which core runs: the compiled one or the pure-Python one (decisions P2, P8).

The hot modules (``CORE``) are compiled by Cython from their own ``.py`` files at install
(setup.py), so one source is both the reference and the compiled path. Python's import
system prefers the extension module next to a ``.py``; where none was built (no compiler
or no Cython at install) the ``.py`` runs.

``ECATSIM_PURE_PYTHON=1`` in the environment makes ``ecatsim`` import the ``.py`` files
instead of the extensions (a meta-path finder installed by ``ecatsim/__init__.py``), so the
daemon runs the pure-Python core: to rule the compiled code in or out when something looks
wrong, at some cost in speed. It also leaves out the compiled-only responder
(``ecatsim/ethercat/responder.pyx``, loaded through :func:`load`).

On a free-threaded interpreter (``python3.13t``) the compiled modules are not imported:
they declare that they need the GIL (``Py_mod_gil``), and the core is not declared safe
with the GIL off, so importing them would turn the GIL back on. The pure-Python core runs
and the daemon says so once in its log.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
import sysconfig
from collections.abc import Sequence
from types import ModuleType

import structlog

log = structlog.get_logger("ecatsim.compiled")

#: the modules of the compiled core, compiled from their .py by setup.py (read there). A
#: module joins with its .pxd types: compiled without them, the ESC, segment, firmware and
#: daemon modules ran no faster than CPython's own interpreter, whose specialised attribute
#: reads beat Cython's generic ones, and the daemon's CPU rose (docs/decisions.md P2, P13)
CORE = (
    "ecatsim.esc.context",
    "ecatsim.esc.sm",
    "ecatsim.esc.fmmu",
    "ecatsim.esc.watchdog",
    "ecatsim.esc.dc",
    "ecatsim.esc.core",
    "ecatsim.esc.pdi",
    "ecatsim.slave.od",
    "ecatsim.slave.pdo",
    "ecatsim.slave.mailbox",
    "ecatsim.slave.firmware",
    "ecatsim.wire.frame",
    "ecatsim.ethercat.recorder",
    "ecatsim.ethercat.logical_index",
    "ecatsim.ethercat.schedule",
    "ecatsim.ethercat.segment",
    "ecatsim.ethercat.prefetch",
    "ecatsim.ethercat.sequence",
    "ecatsim.device.cia402",
    "ecatsim.device.servo",
    "ecatsim.device.drive_od",
    "ecatsim.device.drive",
)

_said_free_threaded = False
_said_pure = False


def pure_python() -> bool:
    """True if the environment asks for the Python reference only."""
    return os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0")


def free_threaded() -> bool:
    """True on a free-threaded (no-GIL) build of CPython."""
    return bool(sysconfig.get_config_var("Py_GIL_DISABLED"))


#: the package folder, and whether it is a source checkout (an editable install), where
#: a compiled module older than its .py is stale and not used
_PACKAGE = os.path.dirname(os.path.abspath(__file__))
_CHECKOUT = os.path.isfile(os.path.join(os.path.dirname(_PACKAGE), "setup.py"))
#: compiled core modules found older than their .py (source checkout only)
stale: list[str] = []


def _built(src: str) -> str | None:
    """The compiled module beside ``src`` (a .py) for this interpreter, if any."""
    stem = src[:-3]
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        if os.path.isfile(stem + suffix):
            return stem + suffix
    return None


class PreferSource(importlib.abc.MetaPathFinder):
    """Import an ``ecatsim`` module from its ``.py`` where the pure-Python core is asked
    for, or, in a source checkout, where the compiled module is older than the ``.py``
    (edited since the last install): the source is the truth."""

    def __init__(self, always: bool) -> None:
        self.always = always

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None,
        target: ModuleType | None = None,
    ) -> importlib.machinery.ModuleSpec | None:
        if not fullname.startswith("ecatsim.") or not path:
            return None
        if not self.always and fullname not in CORE:
            return None
        leaf = fullname.rpartition(".")[2]
        for folder in path:
            src = os.path.join(folder, leaf + ".py")
            if not os.path.isfile(src):
                continue
            if not self.always:
                so = _built(src)
                if so is None or os.path.getmtime(so) >= os.path.getmtime(src):
                    return None  # the compiled module is current: the usual import
                stale.append(fullname)
                log.warning("compiled_module_stale", module=fullname, fix="tools/ensure-venv.sh")
            return importlib.util.spec_from_file_location(fullname, src)
        return None


def _pure_reason() -> str | None:
    if pure_python():
        return "ECATSIM_PURE_PYTHON is set"
    if free_threaded():
        return "free-threaded interpreter: the compiled core needs the GIL"
    return None


def install() -> None:
    """Put :class:`PreferSource` first on ``sys.meta_path``: always the .py where the
    pure-Python core is asked for (or the interpreter is free-threaded), else in a source
    checkout only where a compiled module is stale. Called by ``ecatsim/__init__.py``."""
    if any(isinstance(f, PreferSource) for f in sys.meta_path):
        return
    always = _pure_reason() is not None
    if always or _CHECKOUT:
        sys.meta_path.insert(0, PreferSource(always))


def is_compiled(module: ModuleType) -> bool:
    """True if ``module`` was loaded from a compiled extension."""
    return isinstance(getattr(module, "__loader__", None), importlib.machinery.ExtensionFileLoader)


def core_status() -> tuple[bool, str]:
    """(True, "") if every module of the core runs compiled, else (False, the reason)."""
    reason = _pure_reason()
    if reason is not None:
        return False, reason
    missing = [name for name in CORE if not is_compiled(importlib.import_module(name))]
    if stale:
        return False, f"compiled module older than its source: {', '.join(stale)}; reinstall"
    if missing:
        return False, f"not built for this interpreter: {', '.join(missing)}"
    return True, ""


def core_line() -> str:
    """The second line of ``ecatsim --version``."""
    ok, reason = core_status()
    return "core: compiled" if ok else f"core: pure-python ({reason})"


def say_if_pure() -> None:
    """Log once, at the daemon's start, that the pure-Python core serves (and why)."""
    global _said_pure
    ok, reason = core_status()
    if not ok and not _said_pure:
        _said_pure = True
        log.warning("compiled_core_off", reason=reason, effect="the pure-Python core serves")


def load(name: str) -> ModuleType | None:
    """The optional extension ``name`` (e.g. ``ecatsim.ethercat.responder``), or None where
    it was not built (no C compiler), the environment asks for pure Python, or the
    interpreter is free-threaded."""
    global _said_free_threaded
    if pure_python():
        return None
    if free_threaded():
        if not _said_free_threaded:
            _said_free_threaded = True
            log.warning(
                "compiled_paths_off",
                reason="free-threaded interpreter: the extensions need the GIL",
                effect="the Python reference serves every frame (slower)",
            )
        return None
    try:
        return importlib.import_module(name)
    except ImportError:  # pragma: no cover - built without a C compiler: Python serves
        return None
