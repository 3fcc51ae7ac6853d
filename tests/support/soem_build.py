"""SOEM C programs for the integration tests, built from pysoem's source distribution by
the bench's builder (:mod:`ecatsim.bench.soem`: download, cache, build, substitutions).

:func:`eoe_bridge` is this project's EoE bridge master (tests/support/eoe_bridge.c); the
others are re-exported from the builder.
"""

from __future__ import annotations

from pathlib import Path

from ecatsim.bench.soem import build_program, build_sample, frame_timeout_patch, red_test, soem_tree

__all__ = [
    "FUNCTIONAL_TIMEOUT_US",
    "build_program",
    "build_sample",
    "eoe_bridge",
    "frame_timeout_patch",
    "red_test",
    "soem_tree",
]


#: the frame timeout (SOEM's EC_TIMEOUTRET, 2000 us as shipped) of the C masters in tests
#: about function, not time (the EoE bridge, red_test's WKC test): a reply the host delayed
#: past SOEM's 2 ms costs them nothing; the reply times themselves are the bench's
#: (docs/performance.md) and a wide guard's (decisions K8, K10)
FUNCTIONAL_TIMEOUT_US = 50_000


def eoe_bridge() -> Path:
    """This project's EoE bridge master (tests/support/eoe_bridge.c) on that SOEM, with a
    frame timeout of :data:`FUNCTIONAL_TIMEOUT_US` (a master's own setting)."""
    return build_program("eoe_bridge", [Path(__file__).with_name("eoe_bridge.c")],
                         patches=[frame_timeout_patch(FUNCTIONAL_TIMEOUT_US)])  # fmt: skip
