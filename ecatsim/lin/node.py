"""One TMC211: RAM registers, flags, OTP, dynamic identifiers and the Table 8 state machine.

The bus hands the node every valid header (:meth:`Node.header`), asks it for its answer to
headers it publishes (:meth:`Node.publish`, then :meth:`Node.sent`) and hands it every
complete master frame (:meth:`Node.receive`). Time runs in 1024 µs ticks
(:meth:`Node.advance`). Commands go through the priority encoder of TMC211 §5.1.15
Table 8 (``tables.PRIORITY_ENCODER``); internal events are weighed at each tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ecatsim.lin import codec
from ecatsim.lin.codec import Flags, MotorParams
from ecatsim.lin.config import NodeConfig
from ecatsim.lin.frame import MASTER_REQUEST, SLAVE_RESPONSE, LinError, data_length
from ecatsim.lin.motion import TICK_NS, Motor, Profile, Ramp, wrap16
from ecatsim.lin.otp import Otp, decode, physical_address
from ecatsim.lin.tables import (
    COMMAND_EVENT,
    CURRENT_MA,
    GENERAL_PURPOSE_COMMANDS,
    PREPARABLE,
    PRIORITY_ENCODER,
    PUBLISHED,
    ROM_FRAME_LENGTH,
    SECPOS_DISABLED,
    STEP_RESOLUTION,
    T_LOW_C,
    T_SHUTDOWN_C,
    T_WARNING_C,
    UNITS_PER_FULL_STEP,
    UV2_V,
    Action,
    Cmd,
    Event,
    RomPointer,
    State,
    StepMode,
    acc_units,
    vmax_units,
    vmin_units,
)

MOVING = (State.GOTOPOS, State.RUNINIT, State.SOFTSTOP)
#: writing commands a type #4 frame on 0x3C carries in the type #1 layout, shifted by the
#: AppCMD byte (§6.9.5; decision N9)
APP_COMMANDS = GENERAL_PURPOSE_COMMANDS - {Cmd.SET_POSITION} | {
    Cmd.RUN_INIT,
    Cmd.SET_MOTOR_PARAM,
    Cmd.SET_OTP_PARAM,
}


@dataclass(slots=True)
class RunInit:
    """The reference drive's own registers (§5.1.11, Table 8 note 3)."""

    vmax: int
    vmin: int
    pos1: int
    pos2: int
    phase: int = 1
    deadlock: bool = False


class Node:
    """A TMC211 LIN slave with its motor."""

    def __init__(self, cfg: NodeConfig, now_ns: int) -> None:
        self.name = cfg.name
        self.hw = cfg.hw
        self.otp = Otp(cfg.otp, cfg.otp_file)
        self.motor = Motor(cfg.rotor, cfg.stops, cfg.switch)
        self.ramp = Ramp()
        # physical conditions, set through ``ecatsim ctl`` (§5.1.9, §5.1.10, §5.1.13-14)
        self.temp_c = 25.0
        self.vbat = 12.0
        self.ovc = [False, False]
        self.cp_fault = False
        self.esw_forced: bool | None = None
        self.power_ons = 0
        self.waking = False
        self._t0 = now_ns
        self.power_on(now_ns)

    # --- power ---------------------------------------------------------------------

    def power_on(self, now_ns: int) -> None:
        """Power-on reset: RAM from OTP, <VddReset> set, state ShutDown (Table 8 note 2).

        Leaving Sleep is the same (note 1): dynamic identifiers and positions are RAM."""
        self.power_ons += 1
        self.otp.refresh()
        self._load_ram()
        self.ramp.x = 0.0
        self.ramp.stop()
        self.tagpos = 0
        self.f = dict.fromkeys(
            ("vddreset", "steploss", "eldef", "uv2", "tsd", "tw", "ovc1", "ovc2", "cpfail"), 0
        )
        self.f["vddreset"] = 1
        self.lin_errors = 0
        self.rom_ids: dict[RomPointer, int] = {}
        self.prepared: tuple[int, int] | None = None
        self.sleep_flag = False
        self.stop_flag = False
        self.state = State.SHUTDOWN
        self.runinit: RunInit | None = None
        self.pending_tag: int | None = None
        self.stopped_ns = now_ns - 10**12
        self.next_tick = now_ns + TICK_NS - (now_ns - self._t0) % TICK_NS
        self._sense()

    def _load_ram(self) -> None:
        """OTP to RAM, AccShape reset (§6.11.8, Table 8 ResetToDefault)."""
        o = decode(self.otp.shadow)
        self.ram = MotorParams(
            irun=o.irun,
            ihold=o.ihold,
            vmax=o.vmax,
            vmin=o.vmin,
            secpos=o.secpos,
            shaft=o.shaft,
            acc=o.acc,
            accshape=0,
            stepmode=o.stepmode,
        )
        #: §5.2.3 note: positioning needs a programmed OTP or a SetMotorParam
        self.ram_valid = self.otp.programmed()

    # --- derived registers ---------------------------------------------------------

    @property
    def address(self) -> int:
        """AD[6:0] (§6.5 Table 13), from the OTP shadow and the pins."""
        o = decode(self.otp.shadow)
        return physical_address(o.adm, o.pa, self.hw)

    @property
    def resolution(self) -> int:
        return STEP_RESOLUTION[StepMode(self.ram.stepmode)]

    def actpos(self) -> int:
        """ActPos: the position at the step mode's resolution (§7.3 FAQ)."""
        r = self.resolution
        return wrap16(math.floor(self.ramp.x / r) * r)

    def effective(self, pos: int) -> int:
        """A position field as the controller uses it: LSBs below the resolution dropped."""
        r = self.resolution
        return wrap16(pos // r * r)

    @property
    def secen(self) -> bool:
        """<SecEn> (§5.2.2, Table 8 note 10)."""
        return self.ram.secpos != SECPOS_DISABLED

    def secpos_units(self) -> int:
        return codec.secpos_units(self.ram.secpos)

    @property
    def hs(self) -> bool:
        """<HS> = <CPFail> or <UV2> or <ElDef> (§5.2.2)."""
        return bool(self.f["cpfail"] or self.f["uv2"] or self.f["eldef"])

    def tinfo(self) -> int:
        """Tinfo[1:0] (§5.2.2): 00 normal, 01 low, 10 high warning, 11 shutdown."""
        t = self.temp_c
        if t >= T_SHUTDOWN_C:
            return 0b11
        if t >= T_WARNING_C:
            return 0b10
        return 0b01 if t <= T_LOW_C else 0b00

    def esw(self) -> int:
        """<ESW> (§5.1.9): 1 while the switch is closed."""
        if self.esw_forced is not None:
            return int(self.esw_forced)
        return int(self.motor.switch_closed())

    def flags(self) -> Flags:
        f = self.f
        at = self.actpos() == self.effective(self.tagpos)
        return Flags(
            vddreset=f["vddreset"],
            steploss=f["steploss"],
            eldef=f["eldef"],
            uv2=f["uv2"],
            tsd=f["tsd"],
            tw=f["tw"],
            tinfo=self.tinfo(),
            motion=self.ramp.motion_status(at),
            esw=self.esw(),
            ovc1=f["ovc1"],
            ovc2=f["ovc2"],
            cpfail=f["cpfail"],
        )

    def current_ma(self, now_ns: int) -> int:
        """Coil current: Irun while moving and for one full step at Vmin after a motion,
        then Ihold (§5.3.2); none with the bridges off (ShutDown, Sleep)."""
        if self.state in (State.SHUTDOWN, State.SLEEP):
            return 0
        if self.state != State.STOPPED:
            return CURRENT_MA[self.ram.irun]
        vmin = vmin_units(self.ram.vmin, self.ram.vmax)
        hold_ns = int(UNITS_PER_FULL_STEP / vmin * 1e9)
        if now_ns - self.stopped_ns < hold_ns:
            return CURRENT_MA[self.ram.irun]
        return CURRENT_MA[self.ram.ihold]

    # --- conditions and flags ------------------------------------------------------

    def _sense(self) -> None:
        """Latch the flags of the physical conditions (§5.1.10, §5.1.13, §5.1.14)."""
        if self.state == State.SLEEP:
            return
        f = self.f
        if self.temp_c >= T_WARNING_C:
            f["tw"] = 1
        if self.temp_c >= T_SHUTDOWN_C:
            f["tsd"] = 1
        if self.vbat < UV2_V:
            f["uv2"] = 1
        if self.ovc[0]:
            f["ovc1"] = 1
        if self.ovc[1]:
            f["ovc2"] = 1
        if f["ovc1"] or f["ovc2"]:
            f["eldef"] = 1  # <ElDef> = <OVC1> or <OVC2> (§7.2 FAQ)
        if self.cp_fault:
            f["cpfail"] = 1

    def _clear_flags(self, now_ns: int) -> None:
        """GetStatus/GetFullStatus: flags reset where the conditions allow (Table 8 note 6);
        ShutDown is left once <TSD> and <HS> are clear (note 5)."""
        f = self.f
        f["vddreset"] = 0
        f["steploss"] = 0
        f["tw"] = int(self.temp_c >= T_WARNING_C)
        if self.tinfo() == 0:
            f["tsd"] = 0
        f["uv2"] = int(self.vbat < UV2_V)
        f["ovc1"], f["ovc2"] = int(self.ovc[0]), int(self.ovc[1])
        f["eldef"] = f["ovc1"] | f["ovc2"]
        f["cpfail"] = int(self.cp_fault)
        leave = PRIORITY_ENCODER[Event.GET_STATUS][self.state] == Action.STATUS_LEAVE_SHUTDOWN
        if leave and not f["tsd"] and not self.hs:
            self.state = State.STOPPED  # H-bridges in Ihold mode (§5.1.10)

    def set_condition(self, kind: str, value: float | bool | None, now_ns: int) -> None:
        """A physical condition from ``ecatsim ctl``."""
        self.advance(now_ns)
        if kind == "temp":
            self.temp_c = float(value or 0)
        elif kind == "vbat":
            self.vbat = float(value or 0)
        elif kind in ("ovc1", "ovc2"):
            self.ovc[int(kind[-1]) - 1] = bool(value)
        elif kind == "cpfail":
            self.cp_fault = bool(value)
        elif kind == "esw":
            self.esw_forced = None if value is None else bool(value)
        else:
            raise ValueError(f"unknown condition {kind!r}")
        self._sense()

    # --- bus side ------------------------------------------------------------------

    def header(self, ident: int, now_ns: int) -> None:
        """A valid header on the bus: wakes a sleeping node (power-on, decision N6),
        ends a preparation unless it is the reading frame (§6.9.8), and cancels the
        <Sleep> flag (Table 8 note 4)."""
        if self.state == State.SLEEP:
            self.power_on(now_ns)
            self.waking = True  # the rest of this frame finds the node still waking up
            return
        self.waking = False
        if ident != SLAVE_RESPONSE:
            self.prepared = None
        self.sleep_flag = False

    def lin_error(self, err: LinError) -> None:
        """An error seen on the bus, into the LIN error status register (§6.7)."""
        if self.state != State.SLEEP:
            self.lin_errors |= int(err)

    def _rom_of(self, ident: int) -> RomPointer | None:
        for rom, i in self.rom_ids.items():
            if i == ident and ROM_FRAME_LENGTH[rom] == data_length(ident):
                return rom
        return None

    def publish(self, ident: int, now_ns: int) -> bytes | None:
        """This node's data for a header it publishes, or None."""
        if not self.publishes(ident):
            return None
        self.advance(now_ns)
        self._sense()
        ad = self.address
        if ident == SLAVE_RESPONSE and self.prepared is not None:
            cmd, stage = self.prepared
            if cmd == Cmd.GET_ACTUAL_POS:
                return codec.get_actual_pos_indirect(ad, self.actpos(), self.flags())
            if cmd == Cmd.GET_OTP_PARAM:
                self.otp.refresh()  # Table 8: OTP refresh
                return codec.otp_param(self.otp.shadow, self.hw)
            if stage == 1:
                return codec.full_status_1(ad, self.ram, self.flags(), self.lin_errors)
            return codec.full_status_2(ad, self.actpos(), self.tagpos, self.ram.secpos)
        rom = self._rom_of(ident)
        if rom == RomPointer.GET_ACTUAL_POS:
            return codec.get_actual_pos_direct(ad, self.actpos(), self.flags())
        if rom == RomPointer.GET_STATUS:
            return codec.get_status(ad, self.flags())
        return None

    def publishes(self, ident: int) -> bool:
        """Whether this node answers a header with ``ident`` in its state (Table 8: the
        reading commands answer in every state but Sleep)."""
        if ident == SLAVE_RESPONSE:
            if self.prepared is None:
                return False
            event = COMMAND_EVENT[self.prepared[0]]
        else:
            rom = self._rom_of(ident)
            if rom is None or rom not in PUBLISHED:
                return False
            event = COMMAND_EVENT[Cmd.GET_STATUS if rom == RomPointer.GET_STATUS else 0]
        return PRIORITY_ENCODER[event][self.state] != Action.IGNORED

    def sent(self, ident: int, ok: bool, now_ns: int) -> None:
        """The answer went out (``ok``) or lost the bus to another node (bit error)."""
        if not ok:
            self.lin_errors |= LinError.BIT
        if ident == SLAVE_RESPONSE and self.prepared is not None:
            cmd, stage = self.prepared
            self.prepared = None
            if cmd == Cmd.GET_FULL_STATUS and stage == 1 and ok:
                self._clear_flags(now_ns)  # after the master could read them (note 6)
                self.lin_errors = 0  # §6.7: GetFullStatus resets the register
                self.prepared = (cmd, 2)
        elif ok and self._rom_of(ident) == RomPointer.GET_STATUS:
            self._clear_flags(now_ns)

    # --- master frames -------------------------------------------------------------

    def _addressed(self, b: int) -> bool:
        """Broad = 0 addresses every node; else AD[6:0] must match (§6.5)."""
        return not b & 0x80 or b & 0x7F == self.address

    def _short_addressed(self, b: int) -> bool:
        """SetPositionShort's four address bits; AD[6:4] must be 1 (§6.11.13 Table 17)."""
        return self.address == 0x70 | b & 0x0F

    def receive(self, ident: int, data: bytes, now_ns: int) -> None:
        """A complete master frame with a good checksum."""
        if self.state == State.SLEEP or self.waking:
            return
        self.advance(now_ns)
        if ident == MASTER_REQUEST:
            self._master_request(data, now_ns)
            return
        rom = self._rom_of(ident)
        if rom is None or rom in PUBLISHED:
            return
        if rom in (RomPointer.GENERAL_PURPOSE_2, RomPointer.GENERAL_PURPOSE_4):
            cmd = data[0] & 0x7F
            if cmd in GENERAL_PURPOSE_COMMANDS and self._addressed(data[1]):
                if cmd == Cmd.SET_POSITION and len(data) < 4:
                    return
                self.command(cmd, data[2:], now_ns)
        elif rom == RomPointer.PREPARING:
            if data[0] & 0x7F in PREPARABLE and data[1] & 0x7F == self.address:
                self.prepared = (data[0] & 0x7F, 1)
        elif rom == RomPointer.SET_POSITION:
            self.command(Cmd.SET_POSITION, data[:2], now_ns)
        else:  # SetPositionShort for 1, 2 or 4 motors (§6.11.13)
            for i in range(0, len(data), 2):
                b = data[i]
                one = rom == RomPointer.SET_POSITION_SHORT_1
                if (one and not b & 0x10) or self._short_addressed(b):
                    pos = codec.short_units((b >> 5) << 8 | data[i + 1])
                    self.command(Cmd.SET_POSITION_SHORT_1, bytes(codec.u16(pos)), now_ns)

    def _master_request(self, data: bytes, now_ns: int) -> None:
        """Frames on the reserved identifier 0x3C (§6.8, §6.9.5, §6.9.10, §6.11.15)."""
        if data[0] == codec.SLEEP_BYTE:
            self.event(Event.SLEEP, now_ns)
            return
        if data[0] != codec.APP_CMD:
            return  # another supplier's diagnostic frame
        cmd = data[1] & 0x7F
        if cmd in PREPARABLE:
            if data[2] & 0x7F == self.address:
                self.prepared = (cmd, 1)
        elif cmd == Cmd.SET_POSITION:  # two motors, reserved ID (§6.11.12)
            for i in (2, 5):
                if data[i] & 0x7F == self.address:
                    self.command(cmd, data[i + 1 : i + 3], now_ns)
        elif cmd == Cmd.DYNAMIC_ID:
            if self._addressed(data[2]):
                self.assign_ids(codec.unpack_dynamic_ids(data[3:8]))
        elif cmd in APP_COMMANDS and self._addressed(data[2]):
            self.command(cmd, data[3:], now_ns)

    def assign_ids(self, pairs: list[tuple[int, int]]) -> None:
        """Dynamic identifiers (§6.8): unknown ROM pointers and the reserved identifiers
        0x3C-0x3F are skipped; an identifier serves one ROM pointer (decision N10)."""
        for rom_v, ident in pairs:
            if ident >= MASTER_REQUEST or rom_v not in RomPointer._value2member_map_:
                continue
            rom = RomPointer(rom_v)
            for other, i in list(self.rom_ids.items()):
                if i == ident:
                    del self.rom_ids[other]
            self.rom_ids[rom] = ident

    # --- commands through the priority encoder -------------------------------------

    def _may_position(self) -> bool:
        """§5.2.3 note and §6.11.12: no positioning with unprogrammed RAM, <VddReset>,
        <TSD>, <UV2>, <StepLoss> or <ElDef>."""
        f = self.f
        blocked = f["vddreset"] or f["tsd"] or f["uv2"] or f["steploss"] or f["eldef"]
        return self.ram_valid and not blocked

    def command(self, cmd: int, p: bytes, now_ns: int) -> Action:
        """A writing command with its parameter bytes; returns the Table 8 cell it ran."""
        if cmd == Cmd.SET_OTP_PARAM:  # not in Table 8: any state but Sleep (decision N13)
            self.otp.zap(p[0] & 7, p[1])
            return Action.RAM_UPDATE
        event = COMMAND_EVENT[cmd]
        action = PRIORITY_ENCODER[event][self.state]
        if action == Action.RESET_TO_DEFAULT:
            self.otp.refresh()
            self._load_ram()
            if self.state != State.RUNINIT:
                self.tagpos = self.actpos()  # §6.11.8 note
        elif action == Action.RAM_UPDATE:
            self.ram = codec.decode_motor_params(p)
            self.ram_valid = True
        elif action == Action.RESET_POSITION:
            self.ramp.x = 0.0
            self.tagpos = 0
        elif action in (Action.TAGPOS_GOTO, Action.TAGPOS, Action.SECPOS_GOTO, Action.SECPOS):
            if event == Event.SET_POSITION_SHORT and self.ram.stepmode != StepMode.HALF:
                return Action.IGNORED  # §6.11.13: half-stepping only
            if not self._may_position():
                return Action.IGNORED
            if action in (Action.SECPOS_GOTO, Action.SECPOS):
                if not self.secen:
                    return Action.IGNORED
                pos = self.secpos_units()
            else:
                pos = codec.s16(p[0], p[1])
            if self.state == State.RUNINIT:
                self.pending_tag = pos  # evaluated after RunInit (decision N11)
            else:
                self.tagpos = pos
            if action in (Action.TAGPOS_GOTO, Action.SECPOS_GOTO):
                self.state = State.GOTOPOS
        elif action == Action.TO_RUNINIT:
            if not self.ram_valid or self.f["vddreset"]:
                return Action.IGNORED
            self._start_runinit(p)
        elif action == Action.TO_HARDSTOP_STEPLOSS:
            self.f["steploss"] = 1
            self._hard_stop()
        elif action == Action.TO_SOFTSTOP:
            self.state = State.SOFTSTOP
            self.runinit = None
        return action

    def event(self, event: Event, now_ns: int) -> Action:
        """Sleep command or LIN timeout (Table 8 row "Sleep or LIN timeout")."""
        action = PRIORITY_ENCODER[event][self.state]
        if action == Action.IGNORED:
            return action
        self.sleep_flag = True
        secure = self.secen and not self.f["steploss"] and self.ram_valid
        if action == Action.SLEEP_GOTOPOS:
            if secure:
                self.tagpos = self.secpos_units()
            else:
                self.state = State.SOFTSTOP
        elif action == Action.SLEEP_RUNINIT:
            if self.secen:
                self.pending_tag = self.secpos_units()
        elif action == Action.TO_SLEEP:
            self._enter_sleep()
        return action

    def _start_runinit(self, p: bytes) -> None:
        ri = RunInit(
            vmax=p[0] >> 4, vmin=p[0] & 0xF, pos1=codec.s16(p[1], p[2]), pos2=codec.s16(p[3], p[4])
        )
        # §5.1.11: a first target at the actual position deadlocks the circuit (equal
        # targets do so after the first motion)
        ri.deadlock = self.effective(ri.pos1) == self.actpos()
        self.runinit = ri
        self.pending_tag = None
        self.state = State.RUNINIT

    def _hard_stop(self) -> None:
        self.state = State.HARDSTOP
        self.runinit = None
        self.ramp.stop()

    def _enter_sleep(self) -> None:
        """Everything but the LIN receiver powers down (§5.1.12)."""
        self.ramp.stop()
        self.state = State.SLEEP
        self.runinit = None

    # --- time ----------------------------------------------------------------------

    def busy(self) -> bool:
        """Whether a tick can change anything."""
        st = self.state
        if st in MOVING or st == State.HARDSTOP:
            return True
        if st == State.STOPPED:
            return (
                self.sleep_flag
                or self.stop_flag
                or self.hs
                or bool(self.f["tsd"])
                or self.actpos() != self.effective(self.tagpos)
            )
        if st == State.SHUTDOWN:
            return self.sleep_flag or self.actpos() != self.tagpos
        return False

    def deadline_ns(self) -> int | None:
        return self.next_tick if self.busy() else None

    def advance(self, now_ns: int) -> None:
        """Run the ticks up to ``now_ns``; idle stretches are skipped in one go."""
        while self.next_tick <= now_ns:
            if not self.busy():
                n = (now_ns - self.next_tick) // TICK_NS + 1
                self.next_tick += n * TICK_NS
                return
            self._tick(self.next_tick)
            self.next_tick += TICK_NS

    def _profile(self) -> Profile:
        m = self.ram
        return Profile(
            vmax_units(m.vmax),
            vmin_units(m.vmin, m.vmax),
            acc_units(m.acc, m.vmax),
            bool(m.accshape),
        )

    def _finished(self, action: Action, now_ns: int) -> None:
        """Table 8 row "Motion finished"."""
        if action == Action.TO_STOPPED_KEEP:
            self.ramp.x = float(self.actpos())
            self.tagpos = self.actpos()
            self.stop_flag = True  # note 11
        self.ramp.stop()
        self.state = State.STOPPED
        self.stopped_ns = now_ns

    def _tick(self, now_ns: int) -> None:
        self._sense()
        st = self.state
        if st == State.SLEEP:
            return
        if self._internal_events(st):
            return  # the new state acts from the next tick on
        before = self.actpos()
        if st == State.GOTOPOS:
            self.ramp.step(self.effective(self.tagpos), self._profile())
            self._stepped(before)
            if self.ramp.v == 0.0 and self.actpos() == self.effective(self.tagpos):
                self._finished(PRIORITY_ENCODER[Event.MOTION_FINISHED][st], now_ns)
        elif st == State.RUNINIT:
            self._runinit_tick(now_ns)
        elif st == State.SOFTSTOP:
            done = self.ramp.brake(self._profile())
            self._stepped(before)
            if done:
                self._finished(PRIORITY_ENCODER[Event.MOTION_FINISHED][st], now_ns)
        elif st == State.HARDSTOP:
            self._finished(PRIORITY_ENCODER[Event.MOTION_FINISHED][st], now_ns)
        elif st == State.SHUTDOWN:
            self.ramp.stop()
            self.tagpos = self.actpos()  # §5.1.10
            if self.sleep_flag:
                self._enter_sleep()
        elif st == State.STOPPED:
            self._stopped_tick()

    def _stepped(self, before: int) -> None:
        """The motor follows the steps the driver made (whole steps of the step mode)."""
        moved = wrap16(self.actpos() - before)
        if moved:
            self.motor.move(moved, self.ram.shaft)

    def _internal_events(self, st: State) -> bool:
        """HardStop on <HS>, then thermal shutdown on <TSD>, by Table 8 (the HardStop has
        the higher priority, §5.1.15). Returns whether the state changed."""
        moving = st in MOVING
        if self.hs:
            a = PRIORITY_ENCODER[Event.ELECTRICAL][st]
            if a == Action.TO_SHUTDOWN:
                self.state = State.SHUTDOWN
                return True
            if a == Action.TO_HARDSTOP:
                self.f["steploss"] |= int(moving)
                self._hard_stop()
                return True
        if self.f["tsd"]:
            a = PRIORITY_ENCODER[Event.THERMAL][st]
            if a == Action.TO_SHUTDOWN:
                self.state = State.SHUTDOWN
                return True
            if a == Action.TO_SOFTSTOP:
                self.f["steploss"] |= int(moving)
                self.state = State.SOFTSTOP
                self.runinit = None
                return True
        return False

    def _stopped_tick(self) -> None:
        """State Stopped: <Sleep> (note 9), <Stop> reset (note 11), then the lowest
        priority transition ActPos != TagPos → GotoPos (note 13)."""
        if self.sleep_flag:
            sec = self.secpos_units()
            secure = self.secen and not self.f["steploss"] and self.ram_valid
            if not secure or self.actpos() == self.effective(sec) or self.stop_flag:
                self._enter_sleep()
                return
            self.tagpos = sec
            self.state = State.GOTOPOS
            self.stop_flag = False
            return
        self.stop_flag = False
        if self.actpos() != self.effective(self.tagpos):
            self.state = State.GOTOPOS

    def _runinit_tick(self, now_ns: int) -> None:
        """The two motions of the reference drive, then ActPos = 0 and the secure
        position (§5.1.11, §6.11.9)."""
        ri = self.runinit
        if ri is None or ri.deadlock:
            return
        m = self.ram
        if ri.phase == 1:
            vmin = vmin_units(ri.vmin, ri.vmax)
            prof = Profile(vmax_units(ri.vmax), vmin, acc_units(m.acc, ri.vmax), bool(m.accshape))
            target = self.effective(ri.pos1)
        else:
            v2 = vmin_units(ri.vmin, ri.vmax)
            prof = Profile(v2, v2, acc_units(m.acc, ri.vmax), True)
            target = self.effective(ri.pos2)
        before = self.actpos()
        self.ramp.step(target, prof)
        self._stepped(before)
        if self.ramp.v != 0.0 or self.actpos() != target:
            return
        if ri.phase == 1:
            ri.phase = 2
            ri.deadlock = ri.pos2 == ri.pos1
            return
        self.ramp.x = 0.0  # ResetPosition
        if self.pending_tag is not None:
            self.tagpos = self.pending_tag
        else:
            self.tagpos = self.secpos_units() if self.secen else 0
        self.pending_tag = None
        self.runinit = None
        self._finished(PRIORITY_ENCODER[Event.MOTION_FINISHED][State.RUNINIT], now_ns)

    # --- inspection ----------------------------------------------------------------

    def status(self, now_ns: int) -> dict[str, Any]:
        """What ``ecatsim ctl status`` and ``ctl door lin nodes`` show of the node."""
        self.advance(now_ns)
        flags = [k for k, v in self.f.items() if v]
        if self.sleep_flag:
            flags.append("sleep")
        return {
            "name": self.name,
            "address": self.address,
            "state": self.state.value,
            "actpos": self.actpos(),
            "tagpos": self.tagpos,
            "velocity_fs": round(self.ramp.v / UNITS_PER_FULL_STEP, 1),
            "rotor": round(self.motor.rotor, 1),
            "current_ma": self.current_ma(now_ns),
            "esw": self.esw(),
            "flags": flags,
            "lin_errors": self.lin_errors,
            "ids": {rom.name.lower(): f"0x{i:02X}" for rom, i in sorted(self.rom_ids.items())},
            "otp": self.otp.cells.hex(" "),
            "runinit": None
            if self.runinit is None
            else ("deadlock" if self.runinit.deadlock else f"motion {self.runinit.phase}"),
        }
