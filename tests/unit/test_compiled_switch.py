"""ECATSIM_PURE_PYTHON=1 switches every compiled path off (decisions P2, P9), so the daemon
runs the Python reference only; without it, every extension is in use where it was built.
Ref: ecatsim/compiled.py."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = """
import ecatsim.slave.firmware as firmware
import ecatsim.ethercat.daemon as daemon
print(not firmware.__file__.endswith(".py"), daemon.responder is not None)
"""


def probe(**env: str) -> str:
    full = {k: v for k, v in os.environ.items() if k != "ECATSIM_PURE_PYTHON"}
    full.update(env)
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=full, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_pure_python_switches_every_compiled_path_off() -> None:
    assert probe(ECATSIM_PURE_PYTHON="1") == "False False"


def test_compiled_paths_are_used_where_built() -> None:
    if os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0"):
        pytest.skip("the pure-Python core runs (ECATSIM_PURE_PYTHON)")
    got = probe()
    if got != "True True":
        names = "core, responder"
        msg = f"not every extension was built ({names}: {got})"
        if os.environ.get("CI"):
            pytest.fail(msg, pytrace=False)
        pytest.skip(msg)
    assert probe(ECATSIM_PURE_PYTHON="0") == got


def test_a_free_threaded_interpreter_loads_no_extension(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """On python3.13t the extensions (no Py_mod_gil) are not even imported: one log line."""
    from ecatsim import compiled

    monkeypatch.delenv("ECATSIM_PURE_PYTHON", raising=False)
    monkeypatch.setattr(compiled, "free_threaded", lambda: True)
    monkeypatch.setattr(compiled, "_said_free_threaded", False)
    monkeypatch.delitem(sys.modules, "ecatsim.ethercat.responder", raising=False)
    assert compiled.load("ecatsim.ethercat.responder") is None
    assert "ecatsim.ethercat.responder" not in sys.modules
    assert capsys.readouterr().out.count("compiled_paths_off") == 1
