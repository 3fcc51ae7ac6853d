"""ecatsim: an EtherCAT slave emulator (TMC8460 ESC, TMC8670 CoE servo drive)."""

from __future__ import annotations

__version__ = "0.1.0"

from ecatsim import compiled as _compiled

_compiled.install()  # ECATSIM_PURE_PYTHON=1: the .py modules, not the compiled core
