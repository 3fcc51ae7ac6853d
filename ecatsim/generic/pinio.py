"""A generic slave without a mailbox: IO with no microcontroller behind the ESC. The ESC
runs in device emulation (it answers AL control itself, as such terminals do); after every
frame the inputs go into the input SM's buffer (SAFEOP, OP) and the output SM's buffer into
the outputs (OP), on whatever SMs the ESI puts the process data.

Ref: TMC8460 §5.26 (0x0141 bit 0: device emulation), §5.49 (SM buffers from the PDI side);
ETG.1000.6 §6.4 (AL states in which process data runs).
"""

from __future__ import annotations

from ecatsim.esc.pdi import AL_STATUS, EV_WATCHDOG_PD, WD_STATUS_PD, Pdi
from ecatsim.slave.al import AlState
from ecatsim.slave.pdo import PdoImage

_SAFEOP = int(AlState.SAFEOP)
_OP = int(AlState.OP)


class PinIo:
    """The process image of a mailbox-less slave on its own SMs (Segment.awake)."""

    def __init__(self, pdi: Pdi, app: PdoImage, out_sm: int | None, in_sm: int | None) -> None:
        self.pdi = pdi
        self.app = app
        self.out_sm = out_sm
        self.in_sm = in_sm
        self.state = int(AlState.INIT)
        #: for ctl (od) and the signals, as a firmware has them
        self.od = app.od
        self.device = app.device

    def reset(self) -> None:
        """Power-on or ESC reset: nothing to keep (the ESC holds the AL state)."""
        self.state = int(AlState.INIT)

    def service(self, now_ns: int) -> None:
        p = self.pdi
        if not p.operational():
            return
        if p.al_event() & EV_WATCHDOG_PD:
            p.u8(WD_STATUS_PD)  # acknowledged: no firmware to fall back to SAFEOP
        state = p.u16(AL_STATUS) & 0x0F
        if state != self.state:
            self.state = state
            known = state in (1, 2, 3, 4, 8)
            self.app.al_state_changed(AlState(state) if known else AlState.INIT, now_ns)
        if state == _OP and self.out_sm is not None:
            out = p.sm_read(self.out_sm)
            if out is None:
                out = self._plain(self.out_sm)
            if out is not None:
                self.app.set_outputs(out, now_ns)
        if state in (_SAFEOP, _OP) and self.in_sm is not None:
            data = self.app.get_inputs(now_ns)
            if not p.sm_write(self.in_sm, data):
                s = p.sm_settings(self.in_sm)
                if s.enabled and s.length == 1:  # plain memory (decision R5-12)
                    p.write(s.start, data[:1].ljust(1, b"\x00"))

    def _plain(self, n: int) -> bytes | None:
        """An SM of one byte has no buffer: its byte is plain memory (decision R5-12)."""
        s = self.pdi.sm_settings(n)
        return self.pdi.read(s.start, 1) if s.enabled and s.length == 1 else None
