"""A wide regression guard on the frame path: at most 3x the stored baseline ratio.

Not a timing assertion on absolute numbers: costs are ratios to a calibration loop.
The baseline lives in tests/perf/baseline.json (update it with tools/microbench.py --save).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ecatsim.ethercat import daemon as daemon_mod
from tests.perf.hotpath import calibrate, csp_cycle_cost, frame_cost
from tests.support.compiled import require_built

BASELINE = json.loads((Path(__file__).parent / "baseline.json").read_text())


@pytest.mark.parametrize("n_slaves", [1, 16])
def test_frame_path_not_regressed(n_slaves: int) -> None:
    unit = calibrate()
    ratio = frame_cost(n_slaves, iterations=500) / unit
    base = BASELINE[f"frame_{n_slaves}"]
    assert ratio <= 3 * base, (
        f"{n_slaves} slaves: {ratio:.0f} calibration units vs baseline {base:.0f}"
    )


@pytest.mark.parametrize("drives", [1, 16])
def test_dc_csp_cycle_not_regressed(drives: int) -> None:
    """A DC cycle with enabled TMC8670 drives in csp: SYNC0 pulse, firmware, servo loop and
    the cyclic frame (tools/cycle_profile.py measures the same)."""
    unit = calibrate()
    ratio = csp_cycle_cost(drives, cycles=200) / unit
    base = BASELINE[f"dc_csp_{drives}"]
    assert ratio <= 3 * base, f"{drives} drives: {ratio:.0f} calibration units vs {base:.0f}"


@pytest.mark.parametrize("drives", [1, 16])
def test_dc_csp_cycle_through_the_responder_not_regressed(drives: int) -> None:
    """The same DC cycle with the frame answered by the compiled responder (decision P9)."""
    require_built(daemon_mod.responder, "ecatsim.ethercat.responder")
    unit = calibrate()
    ratio = csp_cycle_cost(drives, cycles=200, responder=True) / unit
    base = BASELINE[f"dc_csp_responder_{drives}"]
    assert ratio <= 3 * base, f"{drives} drives: {ratio:.0f} calibration units vs {base:.0f}"
