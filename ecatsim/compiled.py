"""The switch for the optional compiled paths (decisions P2-P6, P9, P11, P12).

Each compiled path (the servo loop, the drive's steady cycle, the firmware's DC cycle, the
logical datagram walk, the DC time loops and SYNC0 pulses, the raw link's receive, the
daemon's responder) is an optional C extension with its Python original as the reference.
``ECATSIM_PURE_PYTHON=1`` in the environment makes every one of them unavailable, so the
daemon runs the reference model only: to rule the compiled code in or out when something
looks wrong, at some cost in speed.

On a free-threaded interpreter (``python3.13t``) the extensions are not loaded at all: they
do not declare ``Py_mod_gil`` (importing one would turn the GIL back on) and are not safe
with the GIL off. The daemon then runs the Python reference and says so once in its log.
"""

from __future__ import annotations

import importlib
import os
import sysconfig
from types import ModuleType

import structlog

log = structlog.get_logger("ecatsim.compiled")

_said_free_threaded = False


def pure_python() -> bool:
    """True if the environment asks for the Python reference only."""
    return os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0")


def free_threaded() -> bool:
    """True on a free-threaded (no-GIL) build of CPython."""
    return bool(sysconfig.get_config_var("Py_GIL_DISABLED"))


def load(name: str) -> ModuleType | None:
    """The compiled extension ``name`` (e.g. ``ecatsim.esc._logical``), or None where it
    was not built (no C compiler), the environment asks for pure Python, or the
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
