"""The slave firmware: AL state machine and process-data copy, seen through the PDI only.

It runs after the reply has been sent, when the ESC raises a PDI interrupt (AL event
request AND AL event mask), like the microcontroller behind the TMC8460's SPI PDI.
Ref: ETG.1000.6 §6.4 (AL state machine); TMC8460 §2.3.2, §5.20-5.22, §5.32, §5.49.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass

import structlog

from ecatsim.esc.pdi import (
    AL_CONTROL,
    AL_EVENT_MASK,
    AL_STATUS,
    AL_STATUS_CODE,
    DC_ACTIVATION,
    DC_ACTIVATION_STATUS,
    DC_SYNC0_STATUS,
    EV_AL_CONTROL,
    EV_SM0,
    EV_SM_ACTIVATION,
    EV_SYNC0,
    EV_WATCHDOG_PD,
    WD_STATUS_PD,
    Pdi,
    SmSettings,
)
from ecatsim.slave import al
from ecatsim.slave.al import AlState, Transition
from ecatsim.slave.app import Application
from ecatsim.slave.coe import CoeProtocol
from ecatsim.slave.emcy import Emergency
from ecatsim.slave.mailbox import MailboxEngine
from ecatsim.slave.od import ObjectDictionary
from ecatsim.slave.pdo import PdoImage

log = structlog.get_logger("ecatsim.slave")

SM_MBX_OUT = 0
SM_MBX_IN = 1
SM_PD_OUT = 2
SM_PD_IN = 3

#: Control register low nibble (mode + direction) each SM must have.
#: Ref: TMC8460 §5.49 Table 88; ETG.2010 SyncM category types.
CTRL_MBX_OUT = 0x06  # mailbox, ECAT writes
CTRL_MBX_IN = 0x02  # mailbox, ECAT reads
CTRL_PD_OUT = 0x04  # buffered, ECAT writes
CTRL_PD_IN = 0x00  # buffered, ECAT reads

#: the AL states the steady cycle compares with, bound once (compiled: C globals, no enum
#: or module dict lookups; decision P86)
_INIT = AlState.INIT
_SAFEOP = AlState.SAFEOP
_OP = AlState.OP

#: Events the firmware serves (AL event mask). SM1 (mailbox read by the master) is only
#: unmasked while replies are queued. Ref: TMC8460 §5.30, §5.32 Table 46.
EV_SM1 = EV_SM0 << 1
PD_EVENTS = (EV_SM0 << SM_PD_OUT) | (EV_SM0 << SM_PD_IN)  # outputs written, inputs read
EVENT_MASK = EV_AL_CONTROL | EV_SM_ACTIVATION | EV_WATCHDOG_PD | EV_SYNC0 | (0x0D * EV_SM0)
#: SAFEOP -> OP waits for the first outputs this long, then is refused with 0x001B: before
#: the master's own wait (ETG.2000 SafeopOpTimeout, 10 s by default). Decision F5.
OP_WAIT_NS = 9_000_000_000


@dataclass(frozen=True, slots=True)
class MailboxLayout:
    """Where the SII says the mailboxes are (words 0x18-0x1B and 0x14-0x17)."""

    rx_offset: int
    rx_size: int
    tx_offset: int
    tx_size: int
    boot_rx_offset: int = 0
    boot_rx_size: int = 0
    boot_tx_offset: int = 0
    boot_tx_size: int = 0

    @property
    def present(self) -> bool:
        return self.rx_size > 0 and self.tx_size > 0

    @property
    def bootstrap(self) -> bool:
        return self.boot_rx_size > 0 and self.boot_tx_size > 0


class Firmware:
    """AL state machine and process data, for one slave."""

    def __init__(
        self,
        pdi: Pdi,
        app: Application,
        mailbox: MailboxLayout,
        *,
        mbx: MailboxEngine | None = None,
        bootstrap_supported: bool = False,
    ) -> None:
        self.pdi = pdi
        self._app: Application
        self._pdo: PdoImage | None = None
        self.app = app
        self.mailbox = mailbox
        self.mbx = mbx
        self.event_mask = EVENT_MASK
        #: set by the builder for CoE slaves
        self.od: ObjectDictionary | None = None
        self.emergency: Emergency | None = None
        self.device: object | None = None
        self.coe: CoeProtocol | None = None
        #: DC synchronous with the pulses running: SM2/SM3 events wait for SYNC0
        self.pd_masked = False
        #: injected fault: refuse the next state change with this AL status code
        self.refuse_next: int | None = None
        #: outputs (SM2) received since SAFEOP was entered; SAFEOP -> OP waits for them
        self.outputs_seen = False
        #: host time of a SAFEOP -> OP request waiting for the first outputs (0: none)
        self.op_requested_ns = 0
        #: the SYNC0 work latched at a pulse and not run yet (decision P30): the pulse's
        #: time (-1: none) and the outputs taken from SM2 at it, copied into this
        #: firmware's one buffer (valid while ``sync_has_out``; False: no new outputs), so
        #: a frame that writes SM2 before the work runs does not change them (P70)
        self.sync_ns = -1
        self.sync_out = bytearray()
        self.sync_has_out = False
        self.bootstrap_supported = bootstrap_supported
        self.state = AlState.INIT
        self.error = False
        self.code = al.CODE_NONE
        self.log = log.bind(slave=pdi.position)
        self.reset()

    @property
    def app(self) -> Application:
        """The application behind the firmware."""
        return self._app

    @app.setter
    def app(self, app: Application) -> None:
        self._app = app
        #: the same application as a PdoImage, called in C (None: through Python; P32)
        self._pdo = app if isinstance(app, PdoImage) else None

    # ----------------------------------------------------------------- lifecycle

    def reset(self) -> None:
        """Firmware start (power-on or ESC reset): INIT, all SMs locked, events masked.

        Ref: ETG.1000.6 §6.4.1 (INIT after power-on); TMC8460 §5.49 Table 91.
        """
        self.state = AlState.INIT
        self.error = False
        self.code = al.CODE_NONE
        self.outputs_seen = False
        self.op_requested_ns = 0
        self.sync_ns = -1
        self.sync_has_out = False
        p = self.pdi
        if not p.operational():
            return
        self.event_mask = EVENT_MASK
        self.pd_masked = False
        p.w32(AL_EVENT_MASK, EVENT_MASK)
        for n in (SM_MBX_OUT, SM_MBX_IN, SM_PD_OUT, SM_PD_IN):
            p.sm_deactivate(n, True)
        self._publish()

    def al_state_code(self) -> int:
        """The current AL state as its code (for state-dependent OD access)."""
        return int(self.state)

    def _publish(self) -> None:
        status = int(self.state) | (al.AL_ERROR if self.error else 0)
        self.pdi.w16(AL_STATUS_CODE, self.code)
        self.pdi.w16(AL_STATUS, status)

    # ----------------------------------------------------------------- events

    def service(self, now_ns: int) -> None:
        """Serve pending PDI events. Called after the reply to a frame has been sent."""
        p = self.pdi
        if not p.operational():
            return
        if self.sync_ns >= 0:
            self.sync0_run()  # a pulse's work still latched comes first (decision P30)
        ev = p.al_event()
        if ev & EV_AL_CONTROL:
            self._al_control(p.u16(AL_CONTROL), now_ns)
        if ev & EV_SM_ACTIVATION:
            self._sm_activation()
        if ev & EV_WATCHDOG_PD:
            p.u16(WD_STATUS_PD)  # acknowledges the event
            if self.state is _OP:
                self.fail(AlState.SAFEOP, al.CODE_SM_WATCHDOG, now_ns)
        pd_events = ev & PD_EVENTS
        dc = _dc_synchronous(p)
        if dc:
            # DC synchronous: the newest outputs are taken and applied at SYNC0 and the inputs
            # captured there; frames do not wake the firmware (SM2/SM3 events are masked once
            # the pulses run). Ref: ETG.1000.6 §5.3 (DC mode); decision DC3.
            if ev & EV_SYNC0:
                self._latch(p, ev, now_ns)
                self.sync0_run()
            elif pd_events & (EV_SM0 << SM_PD_IN) and p.u8(DC_ACTIVATION_STATUS) & 0x01:
                self._write_inputs(now_ns)  # no pulse yet: keep the inputs fresh meanwhile
        else:
            if ev & (EV_SM0 << SM_PD_OUT):
                out = p.sm_read(SM_PD_OUT)
                if out is not None:
                    self._apply_outputs(out, now_ns)  # free run: when SM2 is written
            if ev & EV_SYNC0:
                p.u8(DC_SYNC0_STATUS)
            if pd_events:
                self._write_inputs(now_ns)
        self.pd_masked = dc and not p.u8(DC_ACTIVATION_STATUS) & 0x01
        self._op_wait(now_ns)
        self.service_mailbox(ev, now_ns)

    def sync0_latch(self, now_ns: int) -> bool:
        """What the firmware does at the SYNC0 pulse itself, in DC synchronous mode: it
        acknowledges the pulse and takes the newest outputs from SM2. The rest of the
        pulse's work (applying them, the drive's cycle, the inputs as of the pulse into SM3)
        is ``sync0_run``, which may come after frames that arrived meanwhile (decision P30).
        A pulse latched while an earlier one's work waits replaces it: the newer outputs,
        if any, and the newer time, as a slave whose cycle overran (the work of the earlier
        pulse is not run). True if work was latched.
        Ref: ETG.1000.6 §5.3 (DC synchronous mode); TMC8460 §5.50.4 (SYNC0 acknowledge).
        """
        p = self.pdi
        if not p.operational():
            return False
        ev = p.al_event()
        if not ev & EV_SYNC0 or not _dc_synchronous(p):
            return False
        self._latch(p, ev, now_ns)
        return True

    def _latch(self, p: Pdi, ev: int, now_ns: int) -> None:
        """The pulse's acknowledge and the outputs taken from SM2 (compiled, this and the
        other per-pulse helpers return a C int, so no error test follows their calls;
        decision P87)."""
        p.u8(DC_SYNC0_STATUS)  # acknowledges the event
        if ev & (EV_SM0 << SM_PD_OUT) and p.sm_read_into(SM_PD_OUT, self.sync_out):
            self.sync_has_out = True  # sm_read's bytes, in the buffer (P70)
        self.sync_ns = now_ns

    def sync0_run(self) -> None:
        """The latched pulse's work, at the pulse's time: the outputs taken at it applied
        (in OP), the inputs as of the pulse written to SM3. Ref: ETG.1000.6 §5.3."""
        now_ns = self.sync_ns  # compiled: a C integer for both calls (decision P60)
        has_out = self.sync_has_out
        self.sync_ns = -1
        self.sync_has_out = False
        if has_out:
            self._apply_outputs(self.sync_out, now_ns)
        self._write_inputs(now_ns)

    def run_latched(self) -> None:
        """``sync0_run`` after the latch (decisions P30, P101), then what ``service`` does
        after a pulse's work: the process-data events masked once the pulses run, the OP
        request that waited too long for outputs failed (F5), and the event mask set again
        where that or the cycle changed it (an EMCY queued behind a full SM1: the SM1 event
        unmasked). Other events of the slave keep its interrupt raised for ``service``."""
        now_ns = self.sync_ns
        self.sync0_run()
        p = self.pdi
        masked = _dc_synchronous(p) and not p.u8(DC_ACTIVATION_STATUS) & 0x01
        self._op_wait(now_ns)
        mbx = self.mbx
        if masked != self.pd_masked or (mbx is not None and mbx.queued()):
            self.pd_masked = masked
            self.service_mailbox(0, now_ns)

    def _op_wait(self, now_ns: int) -> None:
        """An OP request still waiting for outputs OP_WAIT_NS after it fails: SAFEOP with
        0x001B (decision F5)."""
        if self.op_requested_ns and now_ns - self.op_requested_ns >= OP_WAIT_NS:
            self.op_requested_ns = 0
            self.fail(AlState.SAFEOP, al.CODE_SM_WATCHDOG, now_ns)

    def _apply_outputs(self, out: bytes | bytearray, now_ns: int) -> None:
        """Outputs taken from SM2: valid from now on (F5), applied in OP. The process
        image decodes the latched buffer itself; any other application gets bytes."""
        self._outputs_received(now_ns)
        if self.state is _OP:
            pdo = self._pdo
            if pdo is not None:
                pdo.set_outputs(out, now_ns)
            else:
                self._app.set_outputs(out if type(out) is bytes else bytes(out), now_ns)

    def service_mailbox(self, ev: int, now_ns: int) -> None:
        """Serve SM0 (requests) and SM1 (replies taken by the master), then set the event
        mask: SM1 while replies wait, SM2/SM3 not while DC pulses drive the process data.

        Without mailbox protocols a request is read and dropped so the event clears.
        """
        mbx = self.mbx
        want = EVENT_MASK
        if mbx is None:
            if ev & (EV_SM0 << SM_MBX_OUT):
                self.pdi.sm_read(SM_MBX_OUT)
        else:
            if ev & (EV_SM0 << SM_MBX_OUT):
                mbx.receive()
            pending = mbx.pending()  # asked once where nothing is flushed (decision P22)
            if ev & EV_SM1 or pending:
                mbx.flush()  # SM1 read, or replies (EoE frames) waiting for it
                pending = mbx.pending()
            if pending:
                want |= EV_SM1
        if self.pd_masked:
            want &= ~PD_EVENTS
        if want != self.event_mask:
            self.event_mask = want
            self.pdi.w32(AL_EVENT_MASK, want)

    def _sm_activation(self) -> None:
        """Reading the activation registers acknowledges the event. Ref: §5.49 Table 90 *."""
        for n in range(4):
            self.pdi.sm_settings(n)
        if self.mbx is not None and self.state is not _INIT:
            self.mbx.repeat()

    def _outputs_received(self, now_ns: int) -> None:
        """SM2 was written in SAFEOP or OP: the outputs are valid; a SAFEOP -> OP request
        that waited for them completes now (decision F5)."""
        self.outputs_seen = True
        if self.op_requested_ns and self.state is _SAFEOP:
            self.op_requested_ns = 0
            self._enter(Transition.SO, _OP, now_ns)

    def _write_inputs(self, now_ns: int) -> None:
        """The inputs as of ``now_ns`` into SM3: the process image fills the buffer in
        place where it can, else (and for any other application) as bytes (P71)."""
        if self.state is _SAFEOP or self.state is _OP:
            pdo = self._pdo
            p = self.pdi
            if pdo is not None:
                pdo.update_inputs(now_ns)
                if not p.sm_fill(SM_PD_IN, pdo):
                    p.sm_write(SM_PD_IN, pdo.pack_inputs())
            else:
                p.sm_write(SM_PD_IN, self._app.get_inputs(now_ns))

    # ----------------------------------------------------------------- AL control

    def _al_control(self, ctrl: int, now_ns: int) -> None:
        """Handle a state request from AL control 0x0120.

        With the error indicator set and not acknowledged (bit 4), only requests to a
        lower state are executed; INIT always clears the error.
        Ref: ETG.1000.6 §6.4.1.2, §6.4.1.4; TMC8460 §5.20.
        """
        req = al.parse_state(ctrl)
        ack = bool(ctrl & al.AL_ERROR)
        self.op_requested_ns = 0  # a new request replaces one still waiting for outputs
        if req is None:
            self._refuse(al.CODE_UNKNOWN_STATE)
            return
        if self.error and not ack and req != AlState.INIT and al.RANK[req] >= al.RANK[self.state]:
            return
        if ack or req == AlState.INIT:
            self.error = False
            self.code = al.CODE_NONE
        if req == self.state:
            self._publish()
            return
        tr = al.lookup(self.state, req)
        if tr is None:
            self._refuse(al.CODE_INVALID_STATE_CHANGE)
            return
        if self.refuse_next is not None:
            code, self.refuse_next = self.refuse_next, None
            self._refuse(code)  # injected fault
            return
        code = self._check(tr)
        if code:
            self._refuse(code)
            return
        if tr == Transition.SO and not self.outputs_seen and self.app.rx_size() > 0:
            # OP only with valid outputs: SAFEOP until SM2 is first written (decision F5)
            self.op_requested_ns = now_ns or 1
            self.log.info("al_op_waits_for_outputs")
            return
        self._enter(tr, req, now_ns)

    def _refuse(self, code: int) -> None:
        """The one place a refusal becomes error bit + AL status code. Ref: ETG.1000.6 §6.4.1.4."""
        self.error = True
        self.code = code
        self.log.info("al_refused", state=self.state.name, code=f"0x{code:04X}")
        self._publish()

    def fail(self, to: AlState, code: int, now_ns: int) -> None:
        """A local error: drop to ``to`` with the error bit and ``code``. Ref: §6.4.1.4."""
        self.op_requested_ns = 0
        self._stop_for(to, now_ns)
        self.state = to
        self.error = True
        self.code = code
        self.log.warning("al_error", state=to.name, code=f"0x{code:04X}")
        self.app.al_state_changed(to, now_ns)
        self._publish()

    def _check(self, tr: Transition) -> int:
        """Preconditions of a transition, as an AL status code (0 = ok)."""
        if tr == Transition.IP:
            return self.check_mailbox()
        if tr == Transition.IB:
            if not (self.bootstrap_supported and self.mailbox.bootstrap):
                return al.CODE_BOOTSTRAP_NOT_SUPPORTED
            mb = self.mailbox
            s0 = self.pdi.sm_settings(SM_MBX_OUT)
            s1 = self.pdi.sm_settings(SM_MBX_IN)
            if not (
                _mbx_ok(s0, mb.boot_rx_offset, mb.boot_rx_size, CTRL_MBX_OUT)
                and _mbx_ok(s1, mb.boot_tx_offset, mb.boot_tx_size, CTRL_MBX_IN)
            ):
                return al.CODE_INVALID_MBX_BOOT
            return 0
        if tr == Transition.PS:
            prepare = getattr(self.app, "prepare", None)
            code = int(prepare()) if prepare is not None else 0
            return code or self.check_process_data()
        return 0

    def check_mailbox(self) -> int:
        """SM0/SM1 must be enabled mailboxes at the SII offsets, no larger than the SII
        sizes. Ref: ETG.1000.6 §6.4.1.2 (IP checks), AL status code 0x0016."""
        mb = self.mailbox
        if not mb.present:
            return 0
        s0 = self.pdi.sm_settings(SM_MBX_OUT)
        s1 = self.pdi.sm_settings(SM_MBX_IN)
        if not _mbx_ok(s0, mb.rx_offset, mb.rx_size, CTRL_MBX_OUT):
            return al.CODE_INVALID_MBX_PREOP
        if not _mbx_ok(s1, mb.tx_offset, mb.tx_size, CTRL_MBX_IN):
            return al.CODE_INVALID_MBX_PREOP
        return 0

    def check_process_data(self) -> int:
        """SM2/SM3 must be buffered SMs of exactly the process image sizes.

        Ref: ETG.1000.6 §6.4.1.2 (PS checks), AL status codes 0x001D/0x001E.
        """
        rx = self.app.rx_size()
        tx = self.app.tx_size()
        s2 = self.pdi.sm_settings(SM_PD_OUT)
        s3 = self.pdi.sm_settings(SM_PD_IN)
        if not _pd_ok(s2, rx, CTRL_PD_OUT):
            return al.CODE_INVALID_OUTPUT_CONFIG
        if not _pd_ok(s3, tx, CTRL_PD_IN):
            return al.CODE_INVALID_INPUT_CONFIG
        return 0

    def _enter(self, tr: Transition, to: AlState, now_ns: int) -> None:
        """Run a transition's actions and publish the new state. Ref: ETG.1000.6 Table 9."""
        p = self.pdi
        if tr in (Transition.IP, Transition.IB):
            p.sm_deactivate(SM_MBX_OUT, False)
            p.sm_deactivate(SM_MBX_IN, False)
            self.on_mailbox_start()
        elif tr == Transition.PS:
            p.sm_deactivate(SM_PD_OUT, False)
            p.sm_deactivate(SM_PD_IN, False)
            self.outputs_seen = False
            self.state = to
            self._write_inputs(now_ns)
        else:
            self._stop_for(to, now_ns)
        self.state = to
        self.log.info("al_state", state=to.name, transition=tr.name)
        self.app.al_state_changed(to, now_ns)
        self._publish()
        if tr in (Transition.PS, Transition.SO):
            # what the way to SAFEOP and OP built (PDO maps, images) lives as long as the
            # state: out of the cyclic collector, as the daemon's start-up (decision P57)
            gc.freeze()

    def on_mailbox_start(self) -> None:
        """The mailbox starts (IP/IB): counters and queues reset."""
        if self.mbx is not None:
            self.mbx.reset()

    def _stop_for(self, to: AlState, now_ns: int) -> None:
        """Stop what the target state does not run: PD below SAFEOP, mailbox in INIT.
        Leaving OP or SAFEOP forgets the outputs received (OP waits for new ones)."""
        p = self.pdi
        if to != AlState.OP:
            self.outputs_seen = False
        if al.RANK[to] < al.RANK[AlState.SAFEOP] and self.state in (AlState.SAFEOP, AlState.OP):
            p.sm_deactivate(SM_PD_OUT, True)
            p.sm_deactivate(SM_PD_IN, True)
        if to == AlState.INIT:
            p.sm_deactivate(SM_MBX_OUT, True)
            p.sm_deactivate(SM_MBX_IN, True)


def _dc_synchronous(p: Pdi) -> bool:
    """DC synchronous mode: the SYNC unit's activation 0x0981 has the cyclic unit and SYNC0
    on. Ref: TMC8460 §5.50.4 Table 105; ETG.1000.6 §5.3."""
    return (p.u8(DC_ACTIVATION) & 0x03) == 0x03


def _mbx_ok(s: SmSettings, offset: int, size: int, ctrl: int) -> bool:
    return s.enabled and s.start == offset and 0 < s.length <= size and (s.control & 0x0F) == ctrl


def _pd_ok(s: SmSettings, size: int, ctrl: int) -> bool:
    if size == 0:
        return not s.enabled or s.length == 0
    return s.enabled and s.length == size and (s.control & 0x0F) == ctrl
