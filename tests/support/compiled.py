"""Test helpers for the optional compiled paths (decisions P2-P8)."""

from __future__ import annotations

import os
from types import SimpleNamespace
from typing import Any

import pytest


def require_built(module: object, name: str) -> None:
    """Skip a test of extension ``name`` where it was not built; fail under CI, which
    builds every extension (a missing build there is a failure, not a skip)."""
    if module is not None:
        return
    msg = f"{name} was not built (pip install -e . with a C compiler)"
    if os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0"):
        pytest.skip(f"{name}: the pure-Python core runs (ECATSIM_PURE_PYTHON)")
    if os.environ.get("CI"):
        pytest.fail(msg, pytrace=False)
    pytest.skip(msg)


def record_results(
    monkeypatch: pytest.MonkeyPatch, owner: object, attr: str, cls: str, method: str
) -> list[Any]:
    """Replace the extension module ``owner.attr`` for this test by a stand-in whose class
    ``cls`` is a subclass of the real one whose ``method`` records every result, in
    order."""
    real = getattr(owner, attr)
    require_built(real, f"{getattr(owner, '__name__', owner)}.{attr}")
    results: list[Any] = []
    base = getattr(real, cls)

    def recording(self: Any, *args: Any) -> Any:
        r = getattr(base, method)(self, *args)
        results.append(r)
        return r

    stand_in = SimpleNamespace(**{k: getattr(real, k) for k in dir(real) if not k.startswith("__")})
    setattr(stand_in, cls, type(cls, (base,), {method: recording}))  # constants stay as they are
    monkeypatch.setattr(owner, attr, stand_in)
    return results
