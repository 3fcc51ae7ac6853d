"""The MFC CTRL SPI of a TMC8460 on a socket: a microcontroller reaches the MFCIO block.

The protocol is the PDI SPI's (TMC8460 §3.6: "the same as the PDI SPI interface"); the
address is the register number (Table 133) shifted left by 4 plus the byte number. A
frame is one chip select: registers triggered by chip select/deselect move with it, a
register configured for SPI access (configuration bit 4 = 0) takes what is written, and
register 44 (AL_STATE_OVERRIDE, §6.15) is written here only. The MFCIO_IRQ line rises on
the socket beside it (``PATH.irq``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ecatsim.clock import Clock
from ecatsim.mfcio.block import MfcioBlock
from ecatsim.pdi_spi.door import SpiSocket
from ecatsim.pdi_spi.protocol import SpiTiming, transfer

#: how often the IRQ line is looked at while an IRQ client listens (units raise it on
#: their own time, between frames)
IRQ_POLL_NS = 1_000_000
#: no event registers answer during the MFC CTRL address phase (decision S8)
NO_EVENTS = bytes(3)


class MfcSpi:
    """One TMC8460's MFC CTRL SPI on a socket: a front door and the SPI slave's target."""

    def __init__(self, block: MfcioBlock, path: Path, clock: Clock, what: str) -> None:
        self.block = block
        self.clock = clock
        self.socket = SpiSocket(path, self._transfer, what)
        #: frames with an interface error: the MFCIO block has no register counting them
        self.errors = 0
        self._irq = False

    def _transfer(self, mosi: bytes) -> bytes:
        miso = transfer(self, mosi, SpiTiming())
        self._check_irq()
        return miso

    def _check_irq(self) -> None:
        level = bool(self.block.irq.line)
        if level and not self._irq:
            self.socket.raise_irq()
        self._irq = level

    # -- SpiTarget ---------------------------------------------------------------------

    def read(self, addr: int, n: int) -> bytes:
        return self.block.mfc_read(addr, n, self.clock.now_ns())

    def write(self, addr: int, data: bytes) -> bool:
        self.block.mfc_write(addr, data, self.clock.now_ns())
        return True

    def events(self) -> bytes:
        return NO_EVENTS

    def accessed(self) -> None:
        """The MFC CTRL chip select is watched by the MFCIO watchdog inside the block."""

    def interface_error(self, code: int) -> None:
        self.errors += 1

    # -- FrontDoor ---------------------------------------------------------------------

    def fds(self) -> list[int]:
        return self.socket.fds()

    def on_ready(self, fd: int) -> None:
        self.socket.on_ready(fd)

    def service(self, now_ns: int) -> None:
        self._check_irq()

    def deadline_ns(self) -> int | None:
        if self.socket.irq.client is None:
            return None
        return self.clock.now_ns() + IRQ_POLL_NS

    def status(self) -> dict[str, Any]:
        return {**self.socket.status(), "errors": self.errors}

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        raise ValueError(f"the MFC CTRL socket has no command {command!r} (try 'status')")

    def close(self) -> None:
        self.socket.close()
