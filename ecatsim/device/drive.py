"""The TMC8670 CiA 402 drive: PDS state machine, modes pp/pv/hm/csp/csv/cst, faults.

It works on object dictionary values (the PDO copy plan moves them) and advances the
servo on fixed substeps up to the time the process data is exchanged.
Ref: TMC8670 §6-§9 (objects, modes, statusword); CiA 402-2 (PDS FSA §8, modes §10-§12).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import structlog

from ecatsim.device import cia402
from ecatsim.device.cia402 import Command, PdsState
from ecatsim.device.drive_od import DriveOd
from ecatsim.device.servo import (
    POSITION,
    RPM,
    STOP_FOLLOWING,
    STOP_INDEX,
    STOP_NONE,
    STOP_OVERCURRENT,
    TORQUE,
    VELOCITY,
    MotorParams,
    Profile,
    Servo,
    ramp,
)
from ecatsim.slave.al import AlState
from ecatsim.slave.od import Entry, ObjectDictionary

log = structlog.get_logger("ecatsim.drive")

# Modes of operation (6060h). Ref: CiA 402-2 Table 35; TMC8670 §6.1.1.
PP, PV, HM, CSP, CSV, CST = 1, 3, 6, 8, 9, 10
MODES = (0, PP, PV, HM, CSP, CSV, CST)
#: the modes as C integers in the compiled core, for the per-cycle tests (the public names
#: stay Python ints: a module global compared with a C integer converts it every time)
_PP, _PV, _HM, _CSP, _CSV, _CST = PP, PV, HM, CSP, CSV, CST
#: the servo's stop reasons and "no window" (6065h FFFFFFFFh) as C integers, likewise
_STOP_NONE, _STOP_FOLLOWING = STOP_NONE, STOP_FOLLOWING
_STOP_OVERCURRENT, _STOP_INDEX = STOP_OVERCURRENT, STOP_INDEX
_NO_WINDOW = 0xFFFFFFFF
#: the servo's demand kinds as C integers, likewise
_TORQUE, _VELOCITY, _POSITION = TORQUE, VELOCITY, POSITION

# Statusword bits. Ref: TMC8670 Tables 80-83, 81 (Trinamic bits 14/15).
SW_VOLTAGE = 0x0010
SW_WARNING = 0x0080
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_INTERNAL_LIMIT = 0x0800
SW_OMS12 = 0x1000
SW_OMS13 = 0x2000
SW_MOTOR_ACTIVE = 0x4000
SW_DIRECTION = 0x8000

TWO_PI = 2 * math.pi
#: closed current loop time constant the default 2041h gains give (s)
CURRENT_LOOP_TAU = 2.5e-4

#: enum members and tables as module constants: on the per-cycle path an enum's attribute
#: lookup costs more than the comparison it serves
_OE = PdsState.OPERATION_ENABLED
_QSA = PdsState.QUICK_STOP_ACTIVE
_FRA = PdsState.FAULT_REACTION_ACTIVE
_FAULT = PdsState.FAULT
_SOD = PdsState.SWITCH_ON_DISABLED
_SO = PdsState.SWITCHED_ON
_NRTSO = PdsState.NOT_READY_TO_SWITCH_ON
_NO_VOLTAGE = (PdsState.NOT_READY_TO_SWITCH_ON, PdsState.SWITCH_ON_DISABLED, PdsState.FAULT)
_AL_OP = AlState.OP
_POWERED = cia402.POWERED
#: statusword bits 0-3, 5, 6 by the state's value (a tuple index, not an enum's hash)
_STATUS_BITS = tuple([cia402.STATUS_BITS[PdsState(i)] for i in range(len(PdsState))])
_FAULT_RESET = Command.FAULT_RESET
_SWITCH_ON_ENABLE = Command.SWITCH_ON_ENABLE

#: CiA 402 error codes (603Fh) and 1001h bits. Ref: CiA 402-2 Annex; CiA 301 Table 21.
FAULTS: dict[str, tuple[int, int]] = {
    "overcurrent": (0x2310, 0x02),
    "following_error": (0x8611, 0x20),
    "encoder_loss": (0x7305, 0x20),
    "overtemperature": (0x4310, 0x08),
}

Emcy = Callable[[int, int, bytes], None]
#: what the servo is asked to follow: (kind, reference, velocity feed-forward rpm, following
#: error window in counts or 0), see Servo.run
Demand = tuple[int, float, float, float]


def _round(x: float) -> int:
    """``round(x)``: the nearest integer, ties to even. C arithmetic in the compiled core,
    where the builtin is a Python call (nan and infinities raise as round() does)."""
    if not -4.0e18 < x < 4.0e18:
        return round(x)
    return _round_c(x)


def _round_c(x: float) -> int:
    """``round(x)`` for -4e18 < x < 4e18, as a C integer in the compiled core."""
    k = int(x)
    f = x - k  # exact: the fraction of a float
    if f > 0.5 or (f == 0.5 and k & 1):
        k += 1
    elif f < -0.5 or (f == -0.5 and k & 1):
        k -= 1
    return k


def _trunc_c(x: float) -> int:
    """``int(x)`` for -4e18 < x < 4e18, as a C integer in the compiled core."""
    k = int(x)
    return k


def _small(x: float) -> bool:
    """Whether ``_round_c`` takes ``x`` (nan is not)."""
    return -4.0e18 < x < 4.0e18


def _powered(st: PdsState) -> bool:
    """``st in cia402.POWERED``: the drive's state is always one of PdsState's members
    (singletons), so identity decides, without a set lookup per test (decision P23)."""
    return st is _OE or st is _QSA or st is _FRA


def _no_voltage(st: PdsState) -> bool:
    """``st in _NO_VOLTAGE`` by identity (see _powered)."""
    return st is _NRTSO or st is _SOD or st is _FAULT


def _put(d: Drive, k: int, v: int) -> int:
    """Keep ``v``, clamped to the k-th published entry's range, as the drive's k-th
    published value (decisions P34, P38); 0 (compiled: an inline C function whose result
    shows an exception, no test of the thread's error state per call, P51)."""
    lo = d._pub_lo[k]
    hi = d._pub_hi[k]
    d.pub_values[k] = lo if v < lo else hi if v > hi else v
    return 0


def _int_of(e: Entry | None) -> int:
    """An entry's value if it is an int, else 0 (no entry: 0)."""
    if e is None:
        return 0
    v = e.value
    return v if isinstance(v, int) else 0


class Drive(DriveOd):
    """CoeDevice for the TMC8670 (a CycleDevice: the process image calls its cycle in C)."""

    def __init__(
        self,
        od: ObjectDictionary,
        params: MotorParams | None = None,
        emcy: Emcy | None = None,
        emcy_clear: Callable[[], None] | None = None,
        slave: int | None = None,
    ) -> None:
        #: the drive's logger, bound once (a call on the module's lazy logger binds anew
        #: each time), naming the slave's position where the segment gives it
        self.log = log.bind(slave=slave) if slave is not None else log.bind()
        DriveOd.__init__(self, od)
        # OD values the substeps use, read once per advance() (see _snapshot)
        self.q_60ff = self.q_6083 = self.q_6084 = self.q_607a = self.q_60b0 = 0
        self.q_60b1 = self.q_6071 = self.q_60b2 = self.q_6065 = self.q_6085 = 0
        self.q_605a = 0
        #: whether _snapshot read all of them in this advance() (else the mode's own)
        self._snap_all = False
        #: the steady demand _steady_demand() found (kind, reference, feed-forward, window)
        self._d_kind = 0
        self._d_ref = self._d_vff = self._d_window = 0.0
        self.params = params or MotorParams()
        #: the encoder's counts per revolution as a C double (params is fixed for the
        #: drive's life, as substep_ns and the servo derived from it are)
        self._ppr = float(self.params.ppr)
        self.substep_ns = round(self.params.substep * 1e9)
        self.servo = Servo(self.params)
        self.profile = Profile()
        self.emcy = emcy
        self.emcy_clear = emcy_clear
        self.state = _SOD  # transitions 0 and 1 at power-on
        #: statusword bits 0-3, 5, 6 of ``_sw_state`` (None: none yet), see _publish
        self._sw_state: PdsState | None = None
        self._sw_bits = 0
        #: t_ns, last_target and last_t_ns as C numbers with a flag for None (decision
        #: P51: no int or float object made per cycle); the properties give the values
        self._t = 0
        self._t_set = False
        self._lt = 0.0
        self._lt_set = False
        self._ltn = 0
        self._ltn_set = False
        self.prev_cw = 0
        #: the controlword that, repeated, commanded nothing in ``_quiet_state`` (-1 and
        #: None: none yet): _controlword's fast path (decision P75)
        self._quiet_cw = -1
        self._quiet_state: PdsState | None = None
        self.mode = 0
        self._al_state = AlState.INIT
        #: whether the AL state is OP (kept with it: the cycle tests a C flag)
        self._al_op = False
        self.al_state = AlState.INIT
        self.v_demand_rpm = 0.0  # pv / stop ramps
        self.p_demand = 0.0  # counts, position modes
        self.v_ff_rpm = 0.0
        self.set_point_ack = False
        self.homing_done = False
        self.homing_active = False
        self.home_offset_counts = 0.0
        self.active_faults: set[str] = set()
        self.fault_code = 0
        self.injected: set[str] = set()
        self.overcurrent_ma = 0.95 * self.params.max_current_ma
        #: the encoder index output (level, host time ns), wired to a latch input
        self.index_output: Callable[[bool, int], None] | None = None
        #: called with (time, trace_row()) after every input update when tracing
        self.tracer: Callable[[int, tuple[int | str, ...]], None] | None = None
        self._init_od()
        od.refresh = self._publish_sdo_only

    # ----------------------------------------------------------------- OD values
    def _init_od(self) -> None:
        if 0x2020 in self.od:
            self._set(0x2020, 1 if self.params.motor_type == "stepper" else 0, 1)
            self._set(0x2020, self.params.pole_pairs, 2)
        if 0x2081 in self.od:
            self._set(0x2081, self.params.ppr, 2)
        if 0x2041 in self.od and self._v(0x2041, 5) == 0:
            # current loops: pole-zero cancellation for a 250 us closed loop (decision D15)
            p = self.params
            kp, ki = p.inductance / CURRENT_LOOP_TAU, p.resistance / CURRENT_LOOP_TAU
            for sub, value in ((5, kp * 256), (6, ki), (7, kp * 256), (8, ki)):
                self._set(0x2041, min(32767, round(value)), sub)
        if 0x2042 in self.od and self._v(0x2042, 3) == 0:
            self._set(0x2042, round(self.servo.gains.vel_kp * 256), 3)
            self._set(0x2042, round(self.servo.gains.vel_ki), 4)
        if 0x2043 in self.od and self._v(0x2043, 4) == 0:
            self._set(0x2043, round(self.servo.gains.pos_kp * 4096), 4)
        self._publish()

    def _load_gains(self) -> None:
        """Map 2042h/2043h to the loops (see docs/decisions.md D5)."""
        g = self.servo.gains
        if 0x2041 in self.od:
            g.cur_kp = self._v(0x2041, 5) / 256.0
            g.cur_ki = float(self._v(0x2041, 6))
            g.flux_kp = self._v(0x2041, 7) / 256.0
            g.flux_ki = float(self._v(0x2041, 8))
            self.servo.id_ref_ma = float(self._v(0x2041, 3))
        g.vel_kp = self._v(0x2042, 3) / 256.0
        g.vel_ki = float(self._v(0x2042, 4))
        g.pos_kp = self._v(0x2043, 4) / 4096.0
        lim = self.params.max_current_ma
        if 0x6072 in self.od:
            lim = min(lim, self._v(0x6072) or lim)
        if 0x2050 in self.od:
            lim = min(lim, self._v(0x2050, 4))
        self.servo.i_limit_ma = float(lim)
        vmax = float(self._v(0x607F) or 1e9)
        if 0x2050 in self.od:
            vmax = min(vmax, float(self._v(0x2050, 6)))
        self.servo.vel_limit_rpm = vmax

    # ----------------------------------------------------------------- CoeDevice
    def outputs_applied(self, now_ns: int) -> None:
        """New RxPDO values: advance to now, then act on controlword and targets."""
        self.advance(now_ns)
        if self.mode == _CSP:
            if not self._bound:
                self._bind()
            target = float(_int_of(self._c_607a))  # 607Ah
            if self._lt_set and self._ltn_set:
                # C integers and doubles in the compiled core, Python's results (P23)
                now = now_ns
                then = self._ltn
                dt = (now - then) * 1e-9
                if dt > 0:
                    prev = self._lt
                    ppr = self._ppr
                    self.v_ff_rpm = (target - prev) / dt * 60.0 / ppr
            self._lt = target
            self._lt_set = True
            self._ltn = now_ns
            self._ltn_set = True
        self._controlword()

    def update_inputs(self, now_ns: int) -> None:
        self.advance(now_ns)
        self._publish()
        if self.tracer is not None:
            self.tracer(now_ns, self.trace_row())

    def trace_row(self) -> tuple[int | str, ...]:
        """Set points and actual values for the trace. Ref: issue "trace and plot"."""
        mode = self.mode
        if mode in (PV, CSV):
            target_vel = self._v(0x60FF)
        elif mode == CSP:
            target_vel = round(self.v_ff_rpm)  # the velocity the target steps imply
        else:
            target_vel = round(self.profile.vel * 60.0 / self.params.ppr) if mode == PP else 0
        return (
            self._v(0x6040),
            self._v(0x6041),
            mode,
            self.state.name,
            round(self.p_demand),
            self._v(0x6064),
            target_vel,
            self._v(0x606C),
            self._v(0x6071) if mode == CST else round(self.servo.iq_ref_ma),
            self._v(0x6077),
        )

    @property
    def t_ns(self) -> int | None:
        """The time the drive has advanced to (None: not yet)."""
        return self._t if self._t_set else None

    @t_ns.setter
    def t_ns(self, t: int | None) -> None:
        self._t_set = t is not None
        self._t = t if t is not None else 0

    @property
    def last_target(self) -> float | None:
        """The csp position target of the last cycle (None: none since enabling)."""
        return self._lt if self._lt_set else None

    @last_target.setter
    def last_target(self, v: float | None) -> None:
        self._lt_set = v is not None
        self._lt = v if v is not None else 0.0

    @property
    def last_t_ns(self) -> int | None:
        """The time of that target (None: none yet)."""
        return self._ltn if self._ltn_set else None

    @last_t_ns.setter
    def last_t_ns(self, t: int | None) -> None:
        self._ltn_set = t is not None
        self._ltn = t if t is not None else 0

    @property
    def al_state(self) -> AlState:
        """The slave's AL state, as the firmware last reported it."""
        return self._al_state

    @al_state.setter
    def al_state(self, state: AlState) -> None:
        self._al_state = state
        self._al_op = state == _AL_OP

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        """Leaving OP stops the motor (TMC8670 §3.2): quick-stop ramp, voltage off."""
        self.advance(now_ns)
        if self.al_state == _AL_OP and state != _AL_OP:
            if _powered(self.state):
                self._enter(_SOD, "al_left_op")
            self.prev_cw = 0
        self.al_state = state
        self._publish()

    # ----------------------------------------------------------------- faults
    def inject(self, kind: str, active: bool = True) -> None:
        """Inject (or remove) a drive fault cause. Ref: issue "faults"."""
        if kind not in FAULTS:
            raise ValueError(f"unknown drive fault {kind!r} (use: {', '.join(FAULTS)})")
        if active:
            self.injected.add(kind)
            self._fault(kind)
        else:
            self.injected.discard(kind)

    def _fault(self, kind: str) -> None:
        """Transition 13: fault reaction, then fault (14); EMCY, 603Fh, 1001h."""
        if self.state in (_FAULT, _FRA):
            return
        code, reg = FAULTS[kind]
        self.active_faults.add(kind)
        self.fault_code = code
        self.log.warning("drive_fault", kind=kind, code=f"0x{code:04X}")
        if self.emcy is not None:
            self.emcy(code, reg, b"")
        self.state = _FRA
        self.v_demand_rpm = self.servo.rpm

    # ----------------------------------------------------------------- controlword
    def _controlword(self) -> None:
        if not self._bound:
            self._bind()
        cw = _int_of(self._c_6040)  # 6040h
        prev = self.prev_cw
        if cw == prev and cw == self._quiet_cw and self.state is self._quiet_state:
            # the last cycle's controlword again, in a state where it commanded nothing:
            # decode() gives the same command (no edge: no fault reset) and step() the
            # same None (a function of state and command; the mode change below leaves
            # the state), so only the mode and pp's set point can act (decision P75)
            mode = _int_of(self._c_6060)  # 6060h
            if mode != self.mode and mode in MODES:
                self._mode_change(mode)
            if self._al_op and self.state is _OE and self.mode == _PP:
                self._pp_setpoint()
            return
        cmd = cia402.decode(cw, prev)
        self.prev_cw = cw
        mode = _int_of(self._c_6060)  # 6060h
        if mode != self.mode and mode in MODES:
            self._mode_change(mode)
        if not self._al_op:
            return
        # decode() returns Command members and the state is a PdsState member: identity
        # decides (P23, P36)
        if cmd is _FAULT_RESET:
            if self.state is _FAULT and not self.injected:
                self.active_faults.clear()
                self.fault_code = 0
                if self.emcy_clear is not None:
                    self.emcy_clear()
                self._enter(_SOD, "t15")
            return
        tr = cia402.step(self.state, cmd)
        if tr is None:
            if cw == prev:  # repeated, no edge: the same again in this state does nothing
                self._quiet_cw = cw
                self._quiet_state = self.state
            if self.state is _OE and self.mode == _PP:
                self._pp_setpoint()
            return
        number, nxt = tr
        if number == 16 and self._v(0x605A) < 5:
            return  # back to enabled only for quick stop option codes 5-8
        self._enter(nxt, f"t{number}")
        if cmd is _SWITCH_ON_ENABLE and self.state is _SO:
            self._enter(_OE, "t4")

    def _enter(self, nxt: PdsState, why: str) -> None:
        if nxt == _OE and self.state != _QSA:
            self._hold_here()
        if not _powered(nxt):
            self.servo.reset_integrators()
        self.log.info("pds_state", state=nxt.name, why=why)
        self.state = nxt

    def _hold_here(self) -> None:
        """Enable operation: demands start at the actual values (no jump)."""
        self._load_gains()
        s = self.servo
        pos = s.angle / (2 * math.pi) * self.params.ppr
        self.p_demand = pos
        self.profile.pos = pos
        self.profile.target = pos
        self.profile.vel = 0.0
        self.v_demand_rpm = 0.0
        self.last_target = None
        s.reset_integrators()

    def _mode_change(self, mode: int) -> None:
        self.mode = mode
        self.homing_active = False
        if self.state == _OE:
            self._hold_here()

    # ----------------------------------------------------------------- time
    def advance(self, now_ns: int) -> None:
        """Integrate on fixed substeps up to ``now_ns`` (never per frame)."""
        if not self._t_set:
            self._t = now_ns
            self._t_set = True
            return
        # the times as C integers in the compiled core (decision P23)
        now = now_ns
        start = self._t
        dt_ns = self.substep_ns
        n = (now - start) // dt_ns
        if n <= 0:
            return
        s = self.servo
        if (
            not _powered(self.state)
            and s.omega == 0.0
            and s.iq_ma == 0.0
            and abs(self.params.load) <= self.params.coulomb
        ):
            self._t = start + n * dt_ns  # de-energised at rest: nothing moves, skip exactly
            return
        n = min(n, 200_000)  # a long pause is caught up at most 20 s
        self._snapshot()
        index = self.index_output
        t = start
        left = n
        while left > 0:
            steps = left
            if self._steady_demand():
                kind = self._d_kind
                ref = self._d_ref
                v_ff = self._d_vff
                window = self._d_window
            else:  # the demand moves every substep (profiles, ramps)
                kind, ref, v_ff, window = self._substep_demand(self.params.substep)
                steps = 1
            # Servo._run: the substeps done, why it stopped in s.stopped (no tuple, P51)
            done = s._run(steps, kind, ref, v_ff, window, self._trip(), index is not None)
            why = s.stopped
            if why != _STOP_NONE and not self._snap_all:
                # the rest before the fault's EMCY and log, the index pulse, and the ramp
                # that follows a fault (the state leaves Operation enabled only here)
                self._snapshot_all()
            if why == _STOP_FOLLOWING:
                self._fault("following_error")  # this substep still runs on the demand
                more = s._run(1, kind, ref, v_ff, 0.0, self._trip(), index is not None)
                why = s.stopped
                done += more
            left -= done
            t += done * dt_ns
            if why == _STOP_OVERCURRENT:
                self._fault("overcurrent")
            elif why == _STOP_INDEX and index is not None:
                self._index_pulse(index, t)
        if self.state is _OE and self.mode != _PP and self.mode != _CSP:
            self.p_demand = s.angle / TWO_PI * self.params.ppr  # follows the actual
        self._t = start + n * dt_ns if n < 200_000 else now

    def _trip(self) -> float:
        """The current above which a substep ends in an overcurrent fault."""
        return self.overcurrent_ma if _powered(self.state) else math.inf

    def _index_pulse(self, index: Callable[[bool, int], None], t_ns: int) -> None:
        """The encoder's index (N) pulse, once per revolution at angle 0, as wide as one
        count at the present speed. Ref: TMC8670 §5.1.14 (encoder); decision D14."""
        rpm = abs(self.servo.rpm) or 1.0
        width_ns = max(1000, int(60e9 / (self.params.ppr * rpm)))
        index(True, t_ns)
        index(False, t_ns + width_ns)

    def _snapshot(self) -> None:
        """The OD values the substeps use. They only change between advance() calls (PDO
        outputs and SDO writes are applied after advancing), so read them once. Enabled
        in csp, csv or cst, only the mode's own: the steady demand reads no other while
        the state stays; the rest (_snapshot_all) when the servo stops early, before the
        fault, EMCY, log or index pulse, and the ramp after a fault (decision P82)."""
        if not self._bound:
            self._bind()
        self._snap_all = False
        if self.state is _OE:
            mode = self.mode
            if mode == _CSP:
                self.q_607a = _int_of(self._s_607a)
                self.q_60b0 = _int_of(self._s_60b0)
                self.q_6065 = _int_of(self._s_6065)
                return
            if mode == _CSV:
                self.q_60ff = _int_of(self._s_60ff)
                self.q_60b1 = _int_of(self._s_60b1)
                return
            if mode == _CST:
                self.q_6071 = _int_of(self._s_6071)
                self.q_60b2 = _int_of(self._s_60b2)
                return
        self._snapshot_all()

    def _snapshot_all(self) -> None:
        """Every OD value the substeps use (see _snapshot)."""
        self._snap_all = True
        self.q_60ff = _int_of(self._s_60ff)
        self.q_6083 = _int_of(self._s_6083)
        self.q_6084 = _int_of(self._s_6084)
        self.q_607a = _int_of(self._s_607a)
        self.q_60b0 = _int_of(self._s_60b0)
        self.q_60b1 = _int_of(self._s_60b1)
        self.q_6071 = _int_of(self._s_6071)
        self.q_60b2 = _int_of(self._s_60b2)
        self.q_6065 = _int_of(self._s_6065)
        self.q_6085 = _int_of(self._s_6085)
        self.q_605a = _int_of(self._s_605a)

    def _steady_demand(self) -> bool:
        """Whether the servo demand stays the same over the substeps to come (the OD
        values are fixed until the next advance); if so it is in ``_d_kind``, ``_d_ref``,
        ``_d_vff``, ``_d_window`` (C fields in the compiled core, no tuple: decision P35).
        Ref: CiA 402-2 §10-§12."""
        st = self.state
        if not _powered(st):
            return self._demand(_TORQUE, 0.0, 0.0, 0.0)  # voltage off: the motor coasts
        if st is not _OE:  # a PdsState member (P23)
            return False  # quick stop / fault reaction ramps
        mode = self.mode
        if mode == _CSP:
            self.p_demand = float(self.q_607a + self.q_60b0)
            return self._demand(_POSITION, self.p_demand, self.v_ff_rpm, self._window())
        if mode == _CSV:
            v = float(self.q_60ff + self.q_60b1)
            self.v_demand_rpm = v
            return self._demand(_VELOCITY, v, 0.0, 0.0)
        if mode == _CST:
            return self._demand(_TORQUE, float(self.q_6071 + self.q_60b2), 0.0, 0.0)
        if mode == _PV:
            target = 0.0 if self.prev_cw & 0x0100 else float(self.q_60ff)
            return self.v_demand_rpm == target and self._demand(_VELOCITY, target, 0.0, 0.0)
        if mode in (_PP, _HM):
            return False
        return self._demand(_VELOCITY, 0.0, 0.0, 0.0)

    def _demand(self, kind: int, ref: float, v_ff: float, window: float) -> bool:
        """Hold a steady demand (see _steady_demand); True."""
        self._d_kind = kind
        self._d_ref = ref
        self._d_vff = v_ff
        self._d_window = window
        return True

    def _substep_demand(self, dt: float) -> Demand:
        """The demand for one substep where it moves every substep: pp profile, pv ramp,
        homing, and the quick stop / fault reaction ramp (transitions 12 and 14 when the
        ramp ends at standstill). Ref: CiA 402-2 §8 (FSA), §12.3 (pp), §12.5 (pv)."""
        s = self.servo
        st = self.state
        if st in (_QSA, _FRA):
            decel = float(self.q_6085 or 2000)
            self.v_demand_rpm = ramp(self.v_demand_rpm, 0.0, decel, decel, dt)
            if self.v_demand_rpm == 0.0 and abs(s.rpm) < 1.0:
                if st == _FRA:
                    self.state = _FAULT  # transition 14
                elif self.q_605a < 5:
                    self.state = _SOD  # transition 12
            return (VELOCITY, self.v_demand_rpm, 0.0, 0.0)
        halt = bool(self.prev_cw & 0x0100)
        if self.mode == PP:
            prof = self.profile
            if halt:
                prof.target = (
                    prof.pos + math.copysign(prof.vel * prof.vel / (2 * prof.dec), prof.vel)
                    if prof.vel
                    else prof.pos
                )
            prof.step(dt)
            self.p_demand = prof.pos
            return (POSITION, prof.pos, prof.vel / (self.params.ppr / 60.0), self._window())
        if self.mode == PV:
            target = 0.0 if halt else float(self.q_60ff)
            acc = float(self.q_6083 or 1)
            dec = float(self.q_6084 or 1)
            self.v_demand_rpm = ramp(self.v_demand_rpm, target, acc, dec, dt)
            return (VELOCITY, self.v_demand_rpm, 0.0, 0.0)
        return (VELOCITY, self._homing(dt), 0.0, 0.0)

    def _window(self) -> float:
        """Following error window 6065h (0 or FFFFFFFFh: not checked). Ref: CiA 402-2."""
        w = self.q_6065
        return 0.0 if w == _NO_WINDOW else float(w)

    def _pp_setpoint(self) -> None:
        """New set point on the rising edge of bit 4; bit 6 relative. Ref: TMC8670 Table 76."""
        cw = self.prev_cw
        new = bool(cw & 0x10)
        if new and not self.set_point_ack:
            target = float(self._v(0x607A))
            if cw & 0x40:
                target += self.profile.target
            lo, hi = self._v(0x607D, 1), self._v(0x607D, 2)
            if 0x607D in self.od and lo < hi:
                target = max(lo, min(hi, target))
            prof = self.profile
            prof.target = target
            vmax = float(self._v(0x6081) or self._v(0x607F) or 1)
            vmax = min(vmax, float(self._v(0x607F) or vmax))
            cps = self.params.ppr / 60.0
            prof.vmax = vmax * cps
            prof.acc = float(self._v(0x6083) or 1) * cps
            prof.dec = float(self._v(0x6084) or 1) * cps
            self.set_point_ack = True
        elif not new:
            self.set_point_ack = False

    def _homing(self, dt: float) -> float:
        """Homing on the current position (35/37) or on the index pulse (33/34): the
        velocity demand for one substep.

        Ref: CiA 402-2 §11 (homing methods); 6098h, 6099h, 609Ah, 607Ch.
        """
        s = self.servo
        method = self._v(0x6098)
        start = bool(self.prev_cw & 0x10)
        if start and not self.homing_active and not self.homing_done:
            self.homing_active = True
        if not self.homing_active:
            return 0.0
        if method in (35, 37):
            self._home_here()
            return 0.0
        direction = -1.0 if method == 33 else 1.0
        speed = float(self._v(0x6099, 2) or 100)
        acc = float(self._v(0x609A) or 1000)
        self.v_demand_rpm = ramp(self.v_demand_rpm, direction * speed, acc, acc, dt)
        v = self.v_demand_rpm
        # index pulse once per revolution at angle 0 (mod 2 pi): detect the crossing
        after = s.angle + s.omega * dt
        if math.floor(s.angle / TWO_PI) != math.floor(after / TWO_PI):
            self._home_here()
        return v

    def _home_here(self) -> None:
        s = self.servo
        offset = self._v(0x607C)
        pos_counts = s.angle / (2 * math.pi) * self.params.ppr
        # redefine the encoder zero so the current position reads the home offset
        s.angle -= (pos_counts - offset) * 2 * math.pi / self.params.ppr
        self.homing_active = False
        self.homing_done = True
        self.v_demand_rpm = 0.0
        self._hold_here()

    # ----------------------------------------------------------------- statusword
    def _publish(self) -> None:
        """Actual values and the statusword into the OD. Ref: TMC8670 Tables 80-83."""
        s = self.servo
        st = self.state
        if st is not self._sw_state:  # the bits of the state last seen, kept (P83)
            si = st  # the state's value: a C integer in the compiled core
            self._sw_bits = _STATUS_BITS[si]
            self._sw_state = st
        sw = self._sw_bits
        if not _no_voltage(st):
            sw |= SW_VOLTAGE
        if self._al_op:
            sw |= SW_REMOTE
        # the position as a whole float (read_counts() is its int): int(pos_f) where an
        # int is needed, pos_f itself where Python's int - float took it as a double
        pos_f = s.floor_counts()
        rpm = s.read_rpm()
        mode = self.mode
        if st is _OE:
            if mode == _PP:
                prof = self.profile
                window = self._v(0x6067)
                if window == 0xFFFFFFFF:
                    reached = prof.pos == prof.target and prof.vel == 0.0
                elif window == 0:
                    reached = prof.pos == prof.target
                else:
                    reached = prof.pos == prof.target and abs(prof.target - pos_f) <= window
                if reached:
                    sw |= SW_TARGET_REACHED
                if self.set_point_ack:
                    sw |= SW_OMS12
            elif mode == _PV:
                if abs(rpm - self._v(0x60FF)) <= max(1.0, 0.01 * abs(self._v(0x60FF))):
                    sw |= SW_TARGET_REACHED
                if abs(rpm) < 1.0:
                    sw |= SW_OMS12
            elif mode == _HM:
                if self.homing_done:
                    sw |= SW_TARGET_REACHED | SW_OMS12
            elif mode in (_CSP, _CSV, _CST):
                sw |= SW_OMS12  # drive follows the command value
        if abs(s.iq_ref_ma) >= s.i_limit_ma - 1e-6 and _powered(st):
            sw |= SW_INTERNAL_LIMIT
        if self.active_faults and "following_error" in self.active_faults:
            sw |= SW_OMS13
        if abs(rpm) >= 1.0:
            sw |= SW_MOTOR_ACTIVE
        if rpm < -1.0:
            sw |= SW_DIRECTION
        hits = self._published
        if hits is None:
            hits = self._publish_hits()
        if self._pub_c and _small(pos_f):
            pos_c = _trunc_c(pos_f)
            p_demand = self.p_demand
            err = p_demand - pos_c  # Python's float - int: the int as a double
            v_demand = self.v_demand_rpm
            iq = s.iq_ma
            iq_ref = s.iq_ref_ma
            if (
                _small(rpm)
                and _small(p_demand)
                and _small(v_demand)
                and _small(iq)
                and _small(iq_ref)
                and _small(err)
            ):
                # the values below as C integers, kept in the drive (P34); the OD entries
                # get them when something reads the OD, the TxPDO takes them from here (P38)
                _put(self, 0, sw)
                _put(self, 1, mode)
                _put(self, 2, pos_c)
                _put(self, 3, _round_c(rpm))
                _put(self, 4, _round_c(p_demand))
                _put(self, 5, _round_c(v_demand))
                _put(self, 6, _round_c(iq))
                _put(self, 7, _round_c(iq_ref))
                _put(self, 8, _round_c(err))
                _put(self, 9, self.fault_code)
                self.pub_pending = True
                return
        pos = int(pos_f)
        values = (
            sw,
            mode,
            pos,
            _round(rpm),
            _round(self.p_demand),
            _round(self.v_demand_rpm),
            _round(s.iq_ma),
            _round(s.iq_ref_ma),
            _round(self.p_demand - pos),
            self.fault_code,
        )
        self.pub_pending = False  # the entries get these values now
        for k in range(len(values)):
            hit = hits[k]
            if hit is not None:
                v = values[k]
                lo = hit[1]
                hi = hit[2]
                e = hit[0]
                e.value = lo if v < lo else hi if v > hi else v

    def _publish_sdo_only(self) -> None:
        """Values no PDO can carry, refreshed when the OD is read (SDO upload, control
        socket) rather than every cycle. Ref: TMC8670 §5.1.7-5.1.14 (PDO mapping: no)."""
        self.pub_flush()
        s = self.servo
        pos = s.counts
        self._set(0x6063, pos)
        self._set(0x2041, round(s.iq_ref_ma), 1)
        self._set(0x2041, round(s.iq_ma), 2)
        self._set(0x2041, round(s.id_ma), 4)
        self._set(0x2041, round(s.iq_ref_ma - s.iq_ma), 9)
        self._set(0x2041, round(s.iq_integ * 1000.0), 10)  # mV
        self._set(0x2042, round(s.rpm), 2)
        self._set(0x2043, pos, 3)
        self._set(0x2081, pos % self.params.ppr, 3)

    @property
    def velocity_rad_s(self) -> float:
        return self.servo.omega

    @staticmethod
    def rpm_to_rad(rpm: float) -> float:
        return rpm * RPM
