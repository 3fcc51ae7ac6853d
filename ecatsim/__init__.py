"""ecatsim: an EtherCAT slave emulator (TMC8460 ESC, TMC8670 CoE servo drive)."""

from __future__ import annotations

__version__ = "0.1.0"
