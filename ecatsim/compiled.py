"""The switch for the optional compiled paths (decisions P2-P6, P9, P11, P12).

Each compiled path (the servo loop, the drive's steady cycle, the firmware's DC cycle, the
logical datagram walk, the DC time loops and SYNC0 pulses, the raw link's receive, the
daemon's responder) is an optional C extension with its Python original as the reference.
``ECATSIM_PURE_PYTHON=1`` in the environment makes every one of them unavailable, so the
daemon runs the reference model only: to rule the compiled code in or out when something
looks wrong, at some cost in speed.
"""

from __future__ import annotations

import os
from types import ModuleType


def pure_python() -> bool:
    """True if the environment asks for the Python reference only."""
    return os.environ.get("ECATSIM_PURE_PYTHON", "") not in ("", "0")


def available(module: ModuleType | None) -> ModuleType | None:
    """``module`` (an imported extension, or None if it was not built), unless the
    environment asks for pure Python."""
    return None if module is None or pure_python() else module
