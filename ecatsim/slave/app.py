"""The interface between the slave firmware and the application (the device).

Ref: ETG.1000.6 §6.4 (the application behind the AL state machine).
"""

from __future__ import annotations

from typing import Protocol

from ecatsim.slave.al import AlState


class Application(Protocol):
    """A device behind the firmware: it consumes outputs and produces inputs."""

    def rx_size(self) -> int:
        """Bytes of the output process image (RxPDO, SM2)."""
        ...

    def tx_size(self) -> int:
        """Bytes of the input process image (TxPDO, SM3)."""
        ...

    def set_outputs(self, data: bytes, now_ns: int) -> None:
        """New outputs from the master (only called in OP)."""
        ...

    def get_inputs(self, now_ns: int) -> bytes:
        """The current inputs, exactly ``tx_size()`` bytes."""
        ...

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        """The AL state changed; leaving OP must bring outputs to a safe state."""
        ...
