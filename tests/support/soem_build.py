"""SOEM C programs for the integration tests, built from pysoem's source distribution by
the bench's builder (:mod:`ecatsim.bench.soem`: download, cache, build, substitutions).

:func:`eoe_bridge` is this project's EoE bridge master (tests/support/eoe_bridge.c); the
others are re-exported from the builder.
"""

from __future__ import annotations

from pathlib import Path

from ecatsim.bench.soem import build_program, build_sample, red_test, soem_tree

__all__ = ["build_program", "build_sample", "eoe_bridge", "red_test", "soem_tree"]


def eoe_bridge() -> Path:
    """This project's EoE bridge master (tests/support/eoe_bridge.c) on that SOEM."""
    return build_program("eoe_bridge", [Path(__file__).with_name("eoe_bridge.c")])
