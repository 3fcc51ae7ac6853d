"""Test helpers for the compiled core: the same module's .py source loaded beside the
compiled one, for equality tests over one source (decision P2)."""

from __future__ import annotations

import importlib.util
import os
import sys
from types import ModuleType

import pytest

from ecatsim import compiled


def require_compiled(module: ModuleType) -> None:
    """Skip where ``module`` runs from its .py (not built, or the pure-Python core run);
    fail under CI unless the pure-Python core was asked for."""
    if compiled.is_compiled(module):
        return
    msg = f"{module.__name__} runs from its source here ({compiled.core_line()})"
    if os.environ.get("CI") and not compiled.pure_python():
        pytest.fail(msg, pytrace=False)
    pytest.skip(msg)


#: core modules whose classes derive from another core module's classes: their twins
#: derive from that module's twin (a Python class reaches its compiled base's C fields only
#: through the base's own methods, so a twin of the subclass alone cannot run)
BASES: dict[str, tuple[str, ...]] = {"ecatsim.device.drive": ("ecatsim.device.drive_od",)}


def source_twin(module: ModuleType) -> ModuleType:
    """``module`` executed from its .py under another name (``pure:`` prefix): the
    reference the compiled module is compared with. Its own imports are the usual ones,
    but for the modules of its base classes (``BASES``), whose twins it imports."""
    name = "pure:" + module.__name__
    if name in sys.modules:
        return sys.modules[name]
    assert module.__file__ is not None
    src = os.path.splitext(module.__file__)[0].rsplit(".cpython", 1)[0] + ".py"
    spec = importlib.util.spec_from_file_location(name, src)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    bases = BASES.get(module.__name__, ())
    saved = {b: sys.modules[b] for b in bases}
    try:
        for b in bases:
            sys.modules[b] = source_twin(saved[b])
        sys.modules[name] = mod  # dataclasses look their module up while the class is made
        spec.loader.exec_module(mod)
    finally:
        sys.modules.update(saved)
    return mod
