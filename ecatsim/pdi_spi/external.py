"""A slave whose firmware runs outside ecatsim and reaches the chip over the PDI SPI.

ecatsim's own firmware does not run for such a slave: the chip is the bare TMC8460 with
PDI_EMULATION low (TMC8460 §3.5 Table 2), so an AL control request is only an AL event
for the firmware and the AL status changes when the firmware writes it (§5.21, §5.32).
The firmware's SPI frames arrive on a socket (:mod:`ecatsim.pdi_spi.door`); each frame is
decoded by :func:`ecatsim.pdi_spi.protocol.transfer` against the PDI face. Its
complete accesses reload the PDI watchdog (§5.40); the PDI interrupt (AL event request
AND AL event mask, §5.30, §5.32) raises the IRQ line on the socket beside it. On a TMC8460
with MFCIO the MFCIO block sees each frame's chip select and deselect (§6.4 Table 136
triggers 7/8, §6.11.2 WD_CFG bit 1).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from ecatsim.clock import Clock
from ecatsim.esc.pdi import AL_EVENT_MASK, Pdi
from ecatsim.pdi_spi.door import SpiSocket
from ecatsim.pdi_spi.protocol import SpiTiming, transfer

#: 0x0150 bit 5: late data-out sample (§5.28.1 Table 40)
PDI_CONFIG = 0x0150
LATE_SAMPLE = 0x20


class ChipSelect(Protocol):
    """What watches PDI_SPI_CSN beside the SPI slave: the TMC8460's MFCIO block (§6.4)."""

    def pdi_chip_select(self, now_ns: int) -> None: ...

    def pdi_chip_deselect(self, now_ns: int) -> None: ...


class ExternalFirmware:
    """The PDI of one slave on a socket: a segment ``Serviceable`` and a front door."""

    def __init__(self, pdi: Pdi, path: Path, clock: Clock, timing: SpiTiming, what: str) -> None:
        self.pdi = pdi
        self.clock = clock
        self.timing = timing
        self.socket = SpiSocket(path, self._transfer, what)
        #: told of each frame's chip select and deselect (a TMC8460 with MFCIO)
        self.chip_select: ChipSelect | None = None
        self._irq = False
        self._wd_deadline = 0
        self.reset()

    # -- the chip's side ---------------------------------------------------------------

    def reset(self) -> None:
        """Power-up or ESC reset: the PDI watchdog starts over (§5.40)."""
        self._irq = False
        self._arm_watchdog(self.clock.now_ns())

    def service(self, now_ns: int) -> None:
        """Called by the segment while the PDI interrupt is raised and by the loop at the
        watchdog's deadline: raise the IRQ line on a rising edge, expire the watchdog."""
        self._check_irq()
        if self._wd_deadline and now_ns >= self._wd_deadline:
            self._wd_deadline = 0
            self.pdi.set_watchdog_pdi(False)

    def _arm_watchdog(self, now_ns: int) -> None:
        t = self.pdi.watchdog_pdi_ns()
        self._wd_deadline = now_ns + t if t else 0

    def _check_irq(self) -> None:
        level = bool(self.pdi.al_event() & self.pdi.u32(AL_EVENT_MASK))
        if level and not self._irq:
            self.socket.raise_irq()
        self._irq = level

    def _transfer(self, mosi: bytes) -> bytes:
        """One frame: chip select, the datagram, chip deselect (a frame of no bytes is a
        chip select without clocks: the line still toggles)."""
        now = self.clock.now_ns()
        cs = self.chip_select
        if cs is not None:
            cs.pdi_chip_select(now)
        self.pdi.access_time(now)
        late = bool(self.pdi.u8(PDI_CONFIG) & LATE_SAMPLE)
        miso = transfer(self, mosi, self.timing, late)
        if cs is not None:
            cs.pdi_chip_deselect(self.clock.now_ns())
        self._check_irq()
        return miso

    # -- SpiTarget: what the SPI slave reaches ------------------------------------------

    def read(self, addr: int, n: int) -> bytes:
        return self.pdi.read(addr, n)

    def write(self, addr: int, data: bytes) -> bool:
        return self.pdi.write(addr, data)

    def events(self) -> bytes:
        return self.pdi.events()

    def accessed(self) -> None:
        self._arm_watchdog(self.clock.now_ns())
        self.pdi.set_watchdog_pdi(True)

    def interface_error(self, code: int) -> None:
        self.pdi.interface_error(code)

    # -- FrontDoor: the socket in the daemon's loop --------------------------------------

    def fds(self) -> list[int]:
        return self.socket.fds()

    def on_ready(self, fd: int) -> None:
        self.socket.on_ready(fd)

    def deadline_ns(self) -> int | None:
        return self._wd_deadline or None

    def status(self) -> dict[str, Any]:
        return {"slave": self.pdi.position, **self.socket.status()}

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        raise ValueError(f"the PDI socket has no command {command!r} (try 'status')")

    def close(self) -> None:
        self.socket.close()
