"""ECATSIM_PURE_PYTHON=1 switches every compiled path off (decisions P2-P6, P9, P11), so the daemon
runs the Python reference only; without it, every extension is in use where it was built.
Ref: ecatsim/compiled.py."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = """
import ecatsim.slave.cycle as cycle, ecatsim.segment as segment
import ecatsim.daemon as daemon
print(*(m is not None for m in (cycle.compiled, segment._logical, daemon._serve)))
"""


def probe(**env: str) -> str:
    full = {k: v for k, v in os.environ.items() if k != "ECATSIM_PURE_PYTHON"}
    full.update(env)
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=full, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_pure_python_switches_every_compiled_path_off() -> None:
    assert probe(ECATSIM_PURE_PYTHON="1") == "False False False"


def test_compiled_paths_are_used_where_built() -> None:
    if os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0"):
        pytest.skip("the pure-Python core runs (ECATSIM_PURE_PYTHON)")
    got = probe()
    if got != "True True True":
        names = "cycle, logical, serve"
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
    monkeypatch.delitem(sys.modules, "ecatsim.esc._logical", raising=False)
    assert compiled.load("ecatsim.esc._logical") is None
    assert "ecatsim.esc._logical" not in sys.modules
    assert capsys.readouterr().out.count("compiled_paths_off") == 1


def test_the_slot_path_engages_on_this_interpreter() -> None:
    """The C paths read the segment's, the SMs' and the DC units' state at their __slots__
    offsets, found through public API (decision P10), on every interpreter: 3.13 included.
    A property is read by name (-1)."""
    from ecatsim import daemon
    from tests.support.compiled import require_built
    from tests.support.tinymaster import segment_of

    require_built(daemon._serve, "ecatsim._serve")
    assert daemon._serve is not None
    seg, _clock = segment_of(1)
    esc = seg.escs[0]
    for obj, name in ((seg, "escs"), (esc.sm[2], "length"), (esc.dc, "t_ref")):
        assert type(obj).__dict__[name].__class__.__name__ == "member_descriptor"
        assert daemon._serve.slot_offset(obj, name) > 0, (type(obj).__name__, name)
    assert daemon._serve.slot_offset(esc.sm[2], "no_such_attribute") == -1
    assert daemon._serve.slot_offset(seg, "sync_escs") == -1  # a property
