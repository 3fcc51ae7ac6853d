"""The MFCIO block: configuration bytes, shadow registers between the PDRAM memory blocks
and the units, the AL-state gating of inputs and outputs, the emergency switch, the IO
watchdog's forced outputs and the MFC CTRL SPI register access.

The block sits beside the ESC's data path and reaches the PDRAM through its memory bridge
with the behaviour of a PDI (so SyncManagers over MB0/MB1 work as with a
microcontroller); here that is the PDI face (``ecatsim.esc.pdi``). It runs whenever the
ESC's PDI interrupt line is raised (the SM events of MB0 written and MB1 read, SYNC0)
and when asked for its state; between two runs every unit advances by its integer clock
arithmetic, so the result does not depend on when it runs.

Ref: TMC8460 §6.1 (AL-state gating), §6.2 Table 133, §6.4 Tables 135/136 (shadow
registers and triggers), §5.47, §5.53, §6.13, §6.15; decisions M1-M3, M22-M27.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from ecatsim.esc.pdi import (
    AL_STATUS,
    DC_ACTIVATION,
    DC_LATCH0_POS,
    DC_LATCH1_POS,
    DC_NEXT_SYNC1,
    DC_START_TIME,
    DC_SYNC0_STATUS,
    DC_SYNC1_STATUS,
    EV_SM0,
    EV_SM_ACTIVATION,
    EV_SYNC0,
    EV_SYNC1,
    EV_WATCHDOG_PD,
    N_SM,
    WD_STATUS_PD,
    Pdi,
    sm_addr,
)
from ecatsim.mfcio import irq as irqmod
from ecatsim.mfcio import regs as R
from ecatsim.mfcio.config import ECAT_ACCESS, TRIGGER_MASK, Trigger, vector
from ecatsim.mfcio.encoder import Encoder
from ecatsim.mfcio.gpio import Gpio
from ecatsim.mfcio.irq import Irq
from ecatsim.mfcio.parts import Shaft, Wiring
from ecatsim.mfcio.pwm import MARK_A, MARK_B, MARK_CENTER, MARK_START, Pwm
from ecatsim.mfcio.spi import SpiMaster, make_device
from ecatsim.mfcio.stepdir import StepDir
from ecatsim.mfcio.timebase import PWM_TICK_NS, TICK_NS, pwm_ticks, ticks
from ecatsim.mfcio.watchdog import CFG_MFC_CSN, CFG_PDI_CSN, CFG_SOF, OUTPUT_LINES, IoWatchdog

AL_INIT, AL_PREOP, AL_BOOT, AL_SAFEOP, AL_OP = 1, 2, 3, 4, 8
_U64 = struct.Struct("<Q")

#: triggers that move data at every run of the block (the shadow handling cycle runs
#: continuously; a copy of an unchanged value is no write, decision M2)
EVERY_CYCLE = frozenset(
    {
        Trigger.ALWAYS,
        Trigger.BEFORE_CYCLE,
        Trigger.AFTER_CYCLE,
        Trigger.ON_CHANGE,
        Trigger.ALWAYS_15,
    }
)
READABLE = tuple(r for r in R.REGISTERS if not r.writable)
#: registers whose write starts something: taken after the settings of the same shadow
#: cycle, which act together (decision M3)
ACTIONS = ("ENC_X_W", "SPI_TX_DATA", "SD_SR", "SD_ST", "SD_CFG", "WD_TIME")
WRITABLE = tuple(
    sorted(
        (r for r in R.REGISTERS[: R.N_CONFIGURED] if r.writable),
        key=lambda r: (r.name in ACTIONS, r.num),
    )
)
#: PWM IRQ sources by mark (IRQ_CFG bits 4-7)
_MARK_IRQ = {
    MARK_START: irqmod.SRC_PWM_START,
    MARK_CENTER: irqmod.SRC_PWM_CENTER,
    MARK_A: irqmod.SRC_PWM_A,
    MARK_B: irqmod.SRC_PWM_B,
}


class Mcu(Protocol):
    """A microcontroller on the PDI SPI beside the block (TMC8460 §3.1.2): it runs after
    each run of the block and starts over with it."""

    def service(self, now_ns: int) -> None: ...

    def reset(self) -> None: ...


@dataclass(frozen=True, slots=True)
class _Plan:
    """A run's work for one configuration and set of SM windows (see _make_plan)."""

    key: tuple[bytes, tuple[Window, ...] | None]
    w_in: tuple[tuple[int, int, int, int], ...]  # (register, MB0 offset, size, mask)
    r_out: tuple[tuple[int, int, int], ...]  # (register, MB1 offset, size)
    mb0_windows: tuple[tuple[int, int, int, int, int], ...]  # (SM, start, end, s, e)
    mb0_plain: tuple[tuple[int, int], ...]  # MB0 offsets [i, j) outside any window
    mb1_windows: tuple[tuple[int, int, int, int, int], ...]
    mb1_plain: tuple[tuple[int, int], ...]
    take: tuple[tuple[int, int], ...]  # (writable register, trigger) in taking order
    read: tuple[tuple[int, int], ...]  # (readable register, trigger)


@dataclass(frozen=True, slots=True)
class Window:
    """An enabled SyncManager window in process RAM."""

    n: int
    start: int
    end: int
    ecat_writes: bool


class MfcioBlock:
    """One TMC8460's MFCIO block and the parts wired to it."""

    def __init__(self, pdi: Pdi, wiring: Wiring, now_ns: int = 0) -> None:
        self.pdi = pdi
        self.wiring = wiring
        #: called with (now_ns, block) after every run (the --trace writer)
        self.tracer: Callable[[int, MfcioBlock], None] | None = None
        self.t_ns = now_ns
        w = wiring
        self.shaft = Shaft(w.stepper, w.encoder) if w.stepper or w.encoder else None
        self.nes_pin = wiring.nes
        #: the microcontroller on the PDI SPI, if the board has one (``firmware: external``):
        #: it owns the ESC's events, so the block acknowledges none of them (decision M32)
        self.mcu: Mcu | None = None
        self.reset()

    # ------------------------------------------------------------------ lifecycle

    def reset(self) -> None:
        """Power-on or ESC reset: every register to 0, the parts stay where they are
        (the motor does not jump). Ref: TMC8460 §6.4 (reset value 0x00)."""
        w = self.wiring
        t = self.t_ns
        self.enc = Encoder()
        self.spi = SpiMaster([make_device(k) for k in w.spi])
        self.sd = StepDir()
        self.pwm = Pwm()
        self.gpio = Gpio()
        self.gpio.external = list(w.gpio)
        self.irq = Irq()
        self.wd = IoWatchdog()
        self.sd.tick = ticks(t)
        self.wd.start = ticks(t)
        self.pwm.origin = pwm_ticks(t)
        if self.shaft is not None:
            a, b, n = self.shaft.levels(self.shaft.count)
            self.enc.a, self.enc.b, self.enc.n = a, b, n
        self.cfg = bytes(R.N_CONFIGURED)
        self._cfg_raw = b""
        self.shadow = [0] * len(R.REGISTERS)  # shadow registers by number
        self.main = [0] * len(R.REGISTERS)  # what the units last took (writable)
        self.override = 0  # AL_STATE_OVERRIDE (register 44)
        self.state = AL_INIT
        self.mb0 = bytearray(R.MB0_SIZE)
        self.windows: tuple[Window, ...] | None = None
        self._plan: _Plan | None = None
        self.pending: list[tuple[int, int, int]] = []  # (due ns, reg, value): trigger 13
        self.frame_no = self.pdi.frames()[0]
        self._dc = self._dc_marks()
        self._sync_active = False
        self.runs = 0
        self.mb1_writes = 0
        self.emergency = False
        self._sync0_ev = False
        if self.mcu is not None:
            self.mcu.reset()

    # ------------------------------------------------------------------ gating

    def outputs_enabled(self, bit: int) -> bool:
        """A sub-block's outputs are driven only in OP, unless AL_STATE_OVERRIDE frees
        them. Ref: TMC8460 §6.1, §6.15 Table 156."""
        return self.state == AL_OP or bool(self.override & bit)

    def _steps_reach_motor(self) -> bool:
        if not self.outputs_enabled(R.OVERRIDE_STEPDIR):
            return False
        return self.wd.force(OUTPUT_LINES.index("SD_STP")) is None

    # ------------------------------------------------------------------ time

    def advance(self, now_ns: int) -> None:
        """Run every unit to ``now_ns``: steps to the motor, encoder transitions, SPI
        transfers, watchdog expiry, PWM marks, values waiting for a PWM cycle start."""
        while now_ns > self.t_ns:
            nxt = now_ns
            d = self.wd.deadline()
            if d is not None:
                nxt = min(nxt, max(d * TICK_NS, self.t_ns + 1))
            if self.pending:
                nxt = min(nxt, max(min(p[0] for p in self.pending), self.t_ns + 1))
            self._run_to(nxt)

    def _run_to(self, ns: int) -> None:
        """Advance to ``ns``; an SPI transfer armed for a PWM mark starts at the mark."""
        spi = self.spi
        mode = spi.trigger_mode()
        if spi.armed and 1 <= mode <= 5:
            kinds = (MARK_A, MARK_B) if mode == 5 else (mode,)
            at = min(self.pwm.next_mark(k, pwm_ticks(self.t_ns) + 1) for k in kinds)
            at_ns = at * PWM_TICK_NS
            if at_ns <= ns:
                self._run_to_plain(at_ns)
                spi.fire(ticks(at_ns))
        self._run_to_plain(ns)

    def _run_to_plain(self, ns: int) -> None:
        t0 = self.t_ns
        if ns <= t0:
            return
        tick = ticks(ns)
        ev = self.sd.advance(tick)
        if ev.steps and self.shaft is not None and self._steps_reach_motor():
            self.shaft.move(ev.steps, self.enc)
        src = 0
        if ev.target_reached_at is not None:
            src |= irqmod.SRC_SD_TARGET
        self.spi.advance(tick)
        if self.spi.new_data:
            self.spi.new_data = 0
            src |= irqmod.SRC_SPI_DATA
        self.wd.advance(tick)
        if self.wd.timeouts:
            self.wd.timeouts = 0
            src |= irqmod.SRC_WD_TIMEOUT
        if self.enc.events:
            self.enc.events = 0
            src |= irqmod.SRC_ENC_N
        if self.irq.cfg & 0xF0:
            for k in self.pwm.marks_between(pwm_ticks(t0), pwm_ticks(ns)):
                src |= _MARK_IRQ[k]
        if src:
            self.irq.raise_(src)
        self.t_ns = ns
        if self.pending:
            due = [p for p in self.pending if p[0] <= ns]
            if due:
                self.pending = [p for p in self.pending if p[0] > ns]
                for _t, num, value in due:
                    self._take(num, value)
        self._emergency_check()

    # ------------------------------------------------------------------ the run

    def service(self, now_ns: int) -> None:
        """One run: events since the last run, configuration, MB0 into the shadow (OP),
        shadow into the units by their triggers, units into the shadow and MB1
        (SAFEOP/OP). Ref: TMC8460 §6.1, §6.4."""
        self.advance(now_ns)
        pdi = self.pdi
        self.runs += 1
        ev = pdi.al_event()
        if ev & EV_SM_ACTIVATION or self.windows is None:
            self.windows = self._read_windows()
        mcu = self.mcu
        if ev & EV_WATCHDOG_PD and mcu is None:  # for the absent firmware (decision M25)
            pdi.u8(WD_STATUS_PD)
        if ev & (EV_SYNC0 | EV_SYNC1) and mcu is None:  # acknowledge (§5.50.4 Table 106)
            if ev & EV_SYNC0:
                pdi.u8(DC_SYNC0_STATUS)
            if ev & EV_SYNC1:
                pdi.u8(DC_SYNC1_STATUS)
        raw = pdi.read(R.CONFIG_START, R.N_CONFIGURED)
        if raw != self._cfg_raw:
            self._cfg_raw = raw
            self.cfg = vector(raw)
        self.state = pdi.u16(AL_STATUS) & 0x0F
        events: set[int] = set()
        frame_no, frame_ns = pdi.frames()
        if frame_no != self.frame_no:
            self.frame_no = frame_no
            events |= {Trigger.SOF, Trigger.EOF}
            self.wd.event(CFG_SOF, ticks(frame_ns))
        marks = self._dc_marks()
        for trig, old, new in zip(
            (Trigger.SYNC0, Trigger.SYNC1, Trigger.LATCH0, Trigger.LATCH1),
            self._dc,
            marks,
            strict=True,
        ):
            if old != new:
                events.add(trig)
        # 0x0990 is also the start time the master writes while the SYNC unit is off
        active = bool(pdi.u8(DC_ACTIVATION) & 0x01)
        if not (active and self._sync_active):
            events.discard(Trigger.SYNC0)
        sync0_ev = bool(ev & EV_SYNC0)
        if sync0_ev and not (mcu is not None and self._sync0_ev):  # a new pulse's event
            events.add(Trigger.SYNC0)
        self._sync0_ev = sync0_ev
        self._sync_active = active
        self._dc = marks
        self._intake(ev)
        self._transfer_writable(events)
        self._gpio_inputs()
        self._transfer_readable(events)
        self._output_mb1()
        if self.tracer is not None:
            self.tracer(now_ns, self)
        if mcu is not None:
            mcu.service(now_ns)

    def _dc_marks(self) -> tuple[bytes, bytes, bytes, bytes]:
        """Registers that change with a SYNC0/SYNC1 pulse (next pulse times) and a
        LATCH0/LATCH1 edge (positive-edge times), to see those events since the last run."""
        p = self.pdi
        return (
            p.read(DC_START_TIME, 8),
            p.read(DC_NEXT_SYNC1, 8),
            p.read(DC_LATCH0_POS, 16),
            p.read(DC_LATCH1_POS, 16),
        )

    def _ecat(self, num: int) -> bool:
        return bool(self.cfg[num] & ECAT_ACCESS)

    def _trigger(self, num: int) -> int:
        return self.cfg[num] & TRIGGER_MASK

    @property
    def plan(self) -> _Plan:
        """The plan for the current configuration and SM windows."""
        p = self._plan
        if p is None or p.key != (self.cfg, self.windows):
            p = self._plan = self._make_plan()
        return p

    # ------------------------------------------------------------------ MB0 / MB1

    def _read_windows(self) -> tuple[Window, ...]:
        out = []
        for n in range(N_SM):
            s = self.pdi.sm_settings(n)
            if s.enabled and not s.pdi_deactivated and s.length and s.start >= 0x1000:
                ecat_writes = (s.control & 0x0C) == 0x04
                out.append(Window(n, s.start, s.start + s.length, ecat_writes))
        return tuple(out)

    def _make_plan(self) -> _Plan:
        """What each run does with this configuration and these SM windows, worked out
        once: the windows and plain ranges of MB0/MB1, the ECAT-enabled registers with
        their offsets, every register's trigger."""
        cfg = self.cfg
        assert self.windows is not None

        def split(lo: int, size: int, ecat_writes: bool) -> tuple[list[Any], list[Any]]:
            covered = bytearray(size)
            wins = []
            for w in self.windows or ():
                if w.end <= lo or w.start >= lo + size:
                    continue
                s, e = max(w.start, lo), min(w.end, lo + size)
                covered[s - lo : e - lo] = b"\x01" * (e - s)
                if w.ecat_writes == ecat_writes:
                    wins.append((w.n, w.start, w.end, s - lo, e - lo))
            plain = []
            i = 0
            while i < size:
                j = covered.find(0, i)
                if j < 0:
                    break
                k = covered.find(1, j)
                k = size if k < 0 else k
                plain.append((j, k))
                i = k
            return wins, plain

        w_in = tuple(
            (r.num, r.mb - R.MB0_START, r.size, r.mask)
            for r in WRITABLE
            if cfg[r.num] & ECAT_ACCESS and r.mb is not None
        )
        r_out = tuple(
            (r.num, r.mb - R.MB1_START, r.size)
            for r in READABLE
            if r.num < R.N_CONFIGURED and cfg[r.num] & ECAT_ACCESS and r.mb is not None
        )
        mb0_wins, mb0_plain = split(R.MB0_START, R.MB0_SIZE, True)
        mb1_wins, mb1_plain = split(R.MB1_START, R.MB1_SIZE, False)
        return _Plan(
            key=(cfg, self.windows),
            w_in=w_in,
            r_out=r_out,
            mb0_windows=tuple(mb0_wins),
            mb0_plain=tuple(mb0_plain),
            mb1_windows=tuple(mb1_wins),
            mb1_plain=tuple(mb1_plain),
            take=tuple((r.num, cfg[r.num] & TRIGGER_MASK) for r in WRITABLE),
            read=tuple((r.num, cfg[r.num] & TRIGGER_MASK) for r in READABLE if r.num < 44),
        )

    def _intake(self, ev: int) -> None:
        """Read MB0 through the SM windows over it (which acknowledges the master's write)
        and the plain PDRAM beside them; in OP the ECAT-enabled writable registers take
        their shadow values from it. Ref: TMC8460 §5.53.1, §6.1, §6.2."""
        plan = self.plan
        if not plan.w_in:
            return
        pdi = self.pdi
        mb0 = self.mb0
        for n, ws, we, s, e in plan.mb0_windows:
            # a buffer completed since the last read (SM status bit 0, Table 89)
            if pdi.u8(sm_addr(n, 5)) & 0x01 or ev & (EV_SM0 << n) or self.runs == 1:
                data = pdi.read(ws, we - ws)
                off = R.MB0_START - ws
                mb0[s:e] = data[s + off : e + off]
        for i, j in plan.mb0_plain:
            mb0[i:j] = pdi.read(R.MB0_START + i, j - i)
        if self.state != AL_OP:
            return
        shadow = self.shadow
        for num, off, size, mask in plan.w_in:
            shadow[num] = int.from_bytes(mb0[off : off + size], "little") & mask

    def _output_mb1(self) -> None:
        """Write the ECAT-enabled readable registers' shadow values into MB1 (padding and
        registers without ECAT access read 0x00), in SAFEOP and OP only.
        Ref: TMC8460 §5.53.2, §6.1."""
        plan = self.plan
        if self.state not in (AL_SAFEOP, AL_OP) or not plan.r_out:
            return
        img = bytearray(R.MB1_SIZE)
        shadow = self.shadow
        for num, off, size in plan.r_out:
            img[off : off + size] = shadow[num].to_bytes(size, "little")
        pdi = self.pdi
        for _n, ws, we, s, e in plan.mb1_windows:
            data = bytearray(we - ws)
            off = R.MB1_START - ws
            data[s + off : e + off] = img[s:e]
            pdi.write(ws, bytes(data))
        for i, j in plan.mb1_plain:
            pdi.write(R.MB1_START + i, bytes(img[i:j]))
        self.mb1_writes += 1

    # ------------------------------------------------------------------ shadow transfers

    def _transfer_writable(self, events: set[int]) -> None:
        """Shadow -> unit for the writable registers whose trigger fired; trigger 13 waits
        for the next start of a PWM cycle. Ref: TMC8460 §6.4 Table 136."""
        shadow, main = self.shadow, self.main
        for n, trig in self.plan.take:
            v = shadow[n]
            if trig == Trigger.PWM_CYCLE:
                if v != main[n] and not any(p[1] == n and p[2] == v for p in self.pending):
                    at = self.pwm.next_start(pwm_ticks(self.t_ns)) * PWM_TICK_NS
                    self.pending = [p for p in self.pending if p[1] != n]
                    self.pending.append((at, n, v))
            elif (trig in EVERY_CYCLE or trig in events) and v != main[n]:
                self._take(n, v)

    def _take(self, num: int, value: int) -> None:
        """A unit register takes a value (a value equal to the last one is no write)."""
        if value == self.main[num]:
            return
        self.main[num] = value
        r = R.REGISTERS[num]
        tick = ticks(self.t_ns)
        u = r.unit
        if u == "encoder":
            self.enc.write(r.name, value)
        elif u == "spi":
            self.spi.write(r.name, value, tick)
        elif u == "stepdir":
            self.sd.write(r.name, value, tick)
        elif u == "pwm":
            self.pwm.write(r.name, value, pwm_ticks(self.t_ns))
        elif u == "gpio":
            self.gpio.write(r.name, value)
        elif u == "irq":
            self.irq.write(r.name, value)
            self._emergency_check()
        elif u == "watchdog":
            self.wd.write(r.name, value, tick)

    def unit_value(self, num: int, *, consume: bool = True) -> int:
        """A register's value in its unit (the main register). Reading IRQ_FLAGS clears
        its flags but the emergency flag (decision M20 for when that counts as a read)."""
        r = R.REGISTERS[num]
        tick = ticks(self.t_ns)
        name = r.name
        if name == "ENC_STATUS":
            return self.enc.status
        if name == "ENC_X":
            return self.enc.x
        if name == "ENC_LATCH":
            return self.enc.latch
        if name == "SPI_RX_DATA":
            return self.spi.rx
        if name == "SPI_STATUS":
            return self.spi.status(tick)
        if name == "SD_SC":
            return self.sd.sc
        if name == "SD_ST":
            return self.sd.st_readback()
        if name == "GPI_IN_VAL":
            return self.gpio.in_val(self.gpio_pins())
        if name == "IRQ_FLAGS":
            return self.irq.read_flags() if consume else self.irq.flags
        if name == "WD_MAX":
            return self.wd.max
        if name == "WD_CFG":
            return self.wd.cfg_readback
        if name == "AL_STATE_OVERRIDE":
            return self.override
        return self.main[num]

    def _transfer_readable(self, events: set[int]) -> None:
        """Unit -> shadow for the readable registers whose trigger fired (trigger 13: at
        a run after a PWM cycle started, i.e. every run). Ref: TMC8460 §6.4."""
        shadow = self.shadow
        for n, trig in self.plan.read:
            if trig in EVERY_CYCLE or trig in events or trig == Trigger.PWM_CYCLE:
                shadow[n] = self.unit_value(n)

    # ------------------------------------------------------------------ pins

    def gpio_pins(self) -> list[int | None]:
        """Level on each GPIO pin: what the unit drives (or the watchdog forces), else
        what the world drives, else open (None)."""
        drive = self.gpio.driven(self.outputs_enabled(R.OVERRIDE_GPIO), self.emergency)
        out: list[int | None] = []
        for i in range(8):
            lvl = drive[i]
            f = self.wd.force(i)
            if f is not None:
                lvl = f[0] if f[1] else None
            out.append(lvl if lvl is not None else self.gpio.external[i])
        return out

    def _gpio_inputs(self) -> None:
        """The watchdog's input condition on the GPI and encoder lines (Table 153)."""
        if not self.wd.in_mask_pol >> 16:
            return
        lv = 0
        for i, p in enumerate(self.gpio_pins()):
            if p:
                lv |= 1 << i
        lv |= (self.enc.n << 9) | (self.enc.b << 10) | (self.enc.a << 11)
        self.wd.inputs(lv, ticks(self.t_ns))

    def _emergency_check(self) -> None:
        """MFC_nES low while enabled (IRQ_CFG[15]) sets the latched emergency flag; while
        it is set the outputs take their safe values and step/dir freezes.
        Ref: TMC8460 §6.13, §6.9.13, §6.10.4; decision M19."""
        if self.irq.nes_enabled and not self.nes_pin and not self.irq.flags & irqmod.NES:
            self.irq.emergency()
        em = bool(self.irq.flags & irqmod.NES)
        if em != self.emergency:
            self.emergency = em
            self.pwm.emergency = em
            self.sd.freeze(em, ticks(self.t_ns))

    def set_nes(self, level: int, now_ns: int) -> None:
        """Drive the MFC_nES input (from ``ecatsim ctl`` or a test)."""
        self.advance(now_ns)
        self.nes_pin = 1 if level else 0
        self._emergency_check()

    def set_gpio_input(self, pin: int, level: int | None, now_ns: int) -> None:
        """Drive (0/1) or release (None) GPIO pin ``pin`` from outside."""
        self.advance(now_ns)
        self.gpio.external[pin] = level
        self._gpio_inputs()

    def pins(self, now_ns: int) -> dict[str, int | None]:
        """Every output line of Table 152 (None: not driven, high impedance), the
        MFCIO_IRQ line and the inputs, at ``now_ns``."""
        self.advance(now_ns)
        tick = ticks(now_ns)
        out: dict[str, int | None] = {}
        gp = self.gpio_pins()
        for i in range(8):
            out[f"GPO{i}"] = gp[i]
        pw = self.pwm.outputs(pwm_ticks(now_ns))
        pen = self.outputs_enabled(R.OVERRIDE_PWM)
        sen = self.outputs_enabled(R.OVERRIDE_STEPDIR)
        cen = self.outputs_enabled(R.OVERRIDE_SPI)
        cs = self.spi.cs_levels(tick)
        vals: dict[str, int] = {
            **{f"PWM_LS{i}": pw.ls[i] for i in range(3)},
            **{f"PWM_HS{i}": pw.hs[i] for i in range(3)},
            "PWM_PULSE_AB": pw.ab,
            "PWM_PULSE_B": pw.b,
            "PWM_PULSE_CENTER": pw.center,
            "PWM_PULSE_A": pw.a,
            "PWM_PULSE_START": pw.zero,
            "SD_DIR": self.sd.dir_level(),
            "SD_STP": self.sd.stp_level(tick),
            **{f"SPI_CS{i}": cs[i] for i in range(4)},
            "SPI_SDI": 0,
            "SPI_SCK": 1 if self.spi.conf & 0x40 else 0,
        }
        for name, v in vals.items():
            en = pen if name.startswith("PWM") else sen if name.startswith("SD") else cen
            lvl: int | None = v if en else None
            f = self.wd.force(OUTPUT_LINES.index(name))
            if f is not None:
                lvl = f[0] if f[1] else None
            out[name] = lvl
        out["MFCIO_IRQ"] = self.irq.line
        out["nES"] = self.nes_pin
        return out

    # ------------------------------------------------------------------ MFC CTRL SPI

    def mfc_write(self, addr: int, data: bytes, now_ns: int) -> None:
        """An MFC CTRL SPI write from ``addr`` (register << 4 | byte): a writable register
        without ECAT access takes it into its shadow; register 44 is written directly;
        anything else is ignored. Triggers 9/10 fire at chip select/deselect.
        Ref: TMC8460 §3.6, §6.2, §6.4 Table 135 bit 4, §6.15."""
        self.advance(now_ns)
        self.wd.event(CFG_MFC_CSN, ticks(now_ns))
        self._cs_event(Trigger.MFC_CS)
        for i, b in enumerate(data):
            hit = R.by_spi_addr(addr + i)
            if hit is None:
                continue
            r, byte = hit
            if r.num == 44:
                self.override = b & r.mask
                continue
            if not r.writable or self._ecat(r.num):
                continue
            v = self.shadow[r.num] & ~(0xFF << (8 * byte)) | (b << (8 * byte))
            self.shadow[r.num] = v & r.mask
        # registers triggered "always" take the value now: the MFC CTRL SPI works without
        # any EtherCAT traffic (§2.3.3), so it cannot wait for the next frame's run
        if self.windows is None:
            self.windows = self._read_windows()
        self._transfer_writable(set())
        self._cs_event(Trigger.MFC_DESELECT)

    def mfc_read(self, addr: int, n: int, now_ns: int) -> bytes:
        """An MFC CTRL SPI read: every register is readable (its unit value).
        Ref: TMC8460 §6.4 ("read access ... always possible")."""
        self.advance(now_ns)
        self.wd.event(CFG_MFC_CSN, ticks(now_ns))
        self._cs_event(Trigger.MFC_CS)
        out = bytearray()
        cache: dict[int, int] = {}
        for i in range(n):
            hit = R.by_spi_addr(addr + i)
            if hit is None:
                out.append(0)
                continue
            r, byte = hit
            if r.num not in cache:
                cache[r.num] = self.unit_value(r.num)
            out.append((cache[r.num] >> (8 * byte)) & 0xFF)
        self._cs_event(Trigger.MFC_DESELECT)
        return bytes(out)

    def pdi_chip_select(self, now_ns: int) -> None:
        """PDI_SPI_CSN falls (a PDI SPI frame begins): registers with trigger 7 move.
        Ref: TMC8460 §6.4 Table 136."""
        self.advance(now_ns)
        self._cs_event(Trigger.PDI_CS)

    def pdi_chip_deselect(self, now_ns: int) -> None:
        """PDI_SPI_CSN rises (the frame ends): the IO watchdog retriggers if WD_CFG bit 1
        is set, registers with trigger 8 move. Ref: TMC8460 §6.4 Table 136, §6.11.2
        Table 151 (cfg_pdi_csn_enable: "positive edge on PDI_SPI_CSN")."""
        self.advance(now_ns)
        self.wd.event(CFG_PDI_CSN, ticks(now_ns))
        self._cs_event(Trigger.PDI_DESELECT)

    def _cs_event(self, trig: Trigger) -> None:
        """Registers triggered by an SPI chip select/deselect (PDI or MFC CTRL) move now."""
        for r in WRITABLE:
            if self._trigger(r.num) == trig:
                self._take(r.num, self.shadow[r.num])
        for r in READABLE:
            if self._trigger(r.num) == trig:
                self.shadow[r.num] = self.unit_value(r.num)

    # ------------------------------------------------------------------ ecatsim ctl

    def ctl(self, op: str, args: list[str], now_ns: int) -> dict[str, object]:
        """``ecatsim ctl mfcio SLAVE OP ARGS``: status | pins | set gpioN 0/1/open |
        set nes 0/1 | set encoder COUNT (turn the shaft) | read REG | write REG VALUE
        (the MFC CTRL SPI path: register 44 and registers without ECAT access are
        writable there)."""
        if op == "status":
            return self.status(now_ns)
        if op == "pins":
            return {"pins": self.pins(now_ns)}
        if op == "set":
            pin, level = args[0].lower(), args[1].lower()
            if pin == "nes" and level in ("0", "1"):
                self.set_nes(int(level), now_ns)
            elif pin == "encoder" and self.shaft is not None and self.shaft.encoder:
                self.advance(now_ns)
                self.shaft.turn(int(level, 0) - self.shaft.count, self.enc)
            elif pin.startswith("gpio") and pin[4:].isdigit() and 0 <= int(pin[4:]) <= 7:
                lvl = None if level == "open" else int(level)
                if lvl not in (None, 0, 1):
                    raise ValueError(f"set {pin}: level 0, 1 or open")
                self.set_gpio_input(int(pin[4:]), lvl, now_ns)
            else:
                raise ValueError(f"set {pin}: pins are gpio0..gpio7 and nes")
            return {"pins": self.pins(now_ns)}
        if op in ("read", "write"):
            r = R.BY_NAME.get(args[0].upper())
            if r is None:
                raise ValueError(f"{args[0]}: no such MFCIO register (TMC8460 Table 133)")
            if op == "write":
                value = int(args[1], 0)
                self.mfc_write(r.spi_addr(), value.to_bytes(r.size, "little"), now_ns)
            raw = self.mfc_read(r.spi_addr(), r.size, now_ns)
            return {"register": r.name, "value": int.from_bytes(raw, "little")}
        raise ValueError(f"mfcio {op}: use status, pins, set, read or write")

    # ------------------------------------------------------------------ reporting

    def duties(self) -> list[float]:
        """PWM duty cycle of each channel (on clocks / cycle clocks)."""
        return [on / per for on, per in (self.pwm.duty(ch) for ch in range(3))]

    def status(self, now_ns: int) -> dict[str, object]:
        """The block at a glance, for ``ecatsim ctl mfcio`` and the trace."""
        self.advance(now_ns)
        return {
            "al_state": self.state,
            "override": self.override,
            "sd_sc": _s32(self.sd.sc),
            "sd_remaining": self.sd.remaining,
            "sd_sr": self.sd.sr,
            "microsteps": self.shaft.microsteps if self.shaft is not None else None,
            "enc_x": _s32(self.enc.x),
            "enc_latch": _s32(self.enc.latch),
            "enc_status": self.enc.status,
            "pwm_duty": [round(d, 6) for d in self.duties()],
            "gpo": self.gpio.out_val & 0xFF,
            "gpi": self.gpio.in_val(self.gpio_pins()),
            "irq_flags": self.irq.flags,
            "wd_active": self.wd.active,
            "wd_max": self.wd.max,
            "emergency": self.emergency,
            "spi_rx": f"0x{self.spi.rx:016X}",
            "config": self.cfg.hex(),
        }


def _s32(v: int) -> int:
    v &= 0xFFFFFFFF
    return v - (1 << 32) if v & 0x80000000 else v
