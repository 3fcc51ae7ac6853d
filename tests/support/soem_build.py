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
    "functional_sample",
    "red_master",
    "red_test",
    "soem_tree",
]


#: the frame timeout (SOEM's EC_TIMEOUTRET, 2000 us as shipped) of the C masters in tests
#: about function, not time (the EoE bridge, red_test's WKC test, the redundancy ring,
#: SOEM's tools): a reply the host delayed past SOEM's 2 ms costs them nothing; the reply
#: times themselves are the bench's (docs/performance.md) and a wide guard's (decisions
#: K8, K10, K11)
FUNCTIONAL_TIMEOUT_US = 50_000
#: the substitution that gives a SOEM build that timeout (a master's own setting)
FUNCTIONAL = (frame_timeout_patch(FUNCTIONAL_TIMEOUT_US),)


def eoe_bridge() -> Path:
    """This project's EoE bridge master (tests/support/eoe_bridge.c) on that SOEM, with a
    frame timeout of :data:`FUNCTIONAL_TIMEOUT_US`."""
    return _own_master("eoe_bridge")


def red_master() -> Path:
    """This project's redundant-mode master (tests/support/red_master.c) on that SOEM, with
    a frame timeout of :data:`FUNCTIONAL_TIMEOUT_US`."""
    return _own_master("red_master")


def _own_master(name: str) -> Path:
    """tests/support/NAME.c on that SOEM, with a frame timeout of FUNCTIONAL_TIMEOUT_US."""
    return build_program(name, [Path(__file__).with_name(f"{name}.c")], patches=FUNCTIONAL)


def functional_sample(sample: str) -> Path:
    """One of SOEM's own samples (eepromtool, slaveinfo ...) with a frame timeout of
    :data:`FUNCTIONAL_TIMEOUT_US`."""
    return build_sample(sample, patches=FUNCTIONAL)
