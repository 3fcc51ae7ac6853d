"""The compiled core and the pure-Python core are one source (decision P13): the same
``.py`` files run interpreted (``ECATSIM_PURE_PYTHON=1``) and compiled by Cython with the
C types of their ``.pxd`` files. C integers wrap, sign-extend and compare signed against
unsigned where Python's integers do not, so a typing slip changes behaviour only in the
compiled run: this test runs the same DC cycles both ways and compares every reply and
the DC registers byte for byte.

The run is long enough for the 32-bit system time to cross bit 31 (the sign of a C
``int``) and the drives to move through a whole cosine of their targets in csp.
Ref: ecatsim/compiled.py; tests/perf/hotpath.py (CspCycle); TMC8460 §5.50 (DC).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ecatsim import compiled

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import hashlib, logging, sys
import structlog
structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING))
from tests.perf.hotpath import CspCycle
import ecatsim.esc.core as core
c = CspCycle(3)
h = hashlib.sha256()
for i in range(400):
    h.update(c.step())
    for esc in c.seg.escs:
        h.update(esc.peek(0x0900, 0xA0))  # receive times, system time, loop, SYNC unit
        h.update(esc.peek(0x0220, 4))  # AL event request
print(core.__file__.endswith(".py"), c.seg.schedule.sync0_ticks, c.daemon.failures, h.hexdigest())
"""


def run(pure: bool) -> tuple[str, int, int, str]:
    env = {k: v for k, v in os.environ.items() if k != "ECATSIM_PURE_PYTHON"}
    if pure:
        env["ECATSIM_PURE_PYTHON"] = "1"
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    is_py, ticks, failures, digest = out.stdout.split()
    return is_py, int(ticks), int(failures), digest


def test_the_compiled_and_the_pure_python_core_give_the_same_bytes() -> None:
    if compiled.pure_python():
        pytest.skip("the pure-Python core runs (ECATSIM_PURE_PYTHON): nothing to compare")
    got = run(pure=False)
    if got[0] != "False":
        msg = "the compiled core was not built (pip install -e . with Cython and a C compiler)"
        if os.environ.get("CI"):
            pytest.fail(msg, pytrace=False)
        pytest.skip(msg)
    ref = run(pure=True)
    assert ref[0] == "True"
    assert ref[2] == got[2] == 0  # no frame or firmware failure either way
    assert ref[1] == got[1] == 3 * 405  # every SYNC0 pulse once (5 cycles to enable)
    assert got[3] == ref[3], "compiled and pure-Python cores differ (a C typing slip?)"
