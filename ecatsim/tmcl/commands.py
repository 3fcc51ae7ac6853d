"""TMCL commands of the TMCM-1311: what each does to the module and what it answers.

The reply's value is the command's value unless the command reads something (as the
firmware copies the command into its reply first). Status codes as §4.2.1; where the
manual does not say which one a case gets, docs/decisions.md T4 does.

Ref: TMCM-1311 TMCL firmware manual §5.7.1-5.7.39.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ecatsim.tmcl import params
from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.motor import I_RMS_MAX_MA, POSITION, TORQUE, VELOCITY
from ecatsim.tmcl.params import AXIS, BANK0, EEPROM_ONLY, USER_VARS_STORED, Param
from ecatsim.tmcl.program import GLOBAL_IRQ, INTERRUPTS, MEMORY_SIZE, PROGRAM_ONLY
from ecatsim.tmcl.protocol import Command, Reply
from ecatsim.tmcl.refsearch import RefSearch

if TYPE_CHECKING:
    from ecatsim.tmcl.module import Module

Handler = Callable[["Module", Command, bool], "Reply | None"]


def ok(value: int = 0) -> Reply:
    return Reply(P.OK, value)


def err(status: int, value: int = 0) -> Reply:
    return Reply(status, value)


def _loaded(m: Module, value: int, direct: bool) -> Reply:
    """A read: in a program the value goes to the accumulator (§5.5)."""
    if not direct:
        m.interp.load(value)
    return ok(value)


# ----------------------------------------------------------------- motion (§5.7.1-5.7.4)


def _rotate(m: Module, c: Command, sign: int) -> Reply:
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    if not params.ROR_MIN <= c.value <= params.ROR_MAX:
        return err(P.INVALID_VALUE, c.value)
    m.axis.rotate(sign * c.value)
    return ok(c.value)


def ror(m: Module, c: Command, direct: bool) -> Reply:
    return _rotate(m, c, 1)


def rol(m: Module, c: Command, direct: bool) -> Reply:
    return _rotate(m, c, -1)


def mst(m: Module, c: Command, direct: bool) -> Reply:
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    if m.axis.home_search is not None:
        m.axis.home_search = None
    m.axis.stop()
    return ok(c.value)


def mvp(m: Module, c: Command, direct: bool) -> Reply:
    """MVP ABS/REL/COORD (§5.7.4); REL from the point axis parameter 127 chooses (§8.4)."""
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    ax = m.axis
    if c.type == 0:
        target = c.value
    elif c.type == 1:
        base = {0: ax.target, 1: round(ax.pos), 2: ax.actual()}[m.ap[127]]
        if ax.mode != POSITION and m.ap[127] == 0:
            base = ax.actual()
        target = P.to_signed(base + c.value)
    elif c.type == 2:
        if not 0 <= c.value < len(m.coords):
            return err(P.INVALID_VALUE, c.value)
        target = m.coords[c.value]
    else:
        return err(P.WRONG_TYPE, c.value)
    ax.home_search = None
    ax.move_to(target)
    return ok(c.value)


# ----------------------------------------------------------------- axis parameters


def read_axis(m: Module, n: int) -> int:
    """The value GAP ``n`` reads: RAM for settings, live state for the rest (§6)."""
    ax = m.axis
    live: dict[int, Callable[[], int]] = {
        0: lambda: ax.target,
        1: ax.actual,
        2: ax.target_speed,
        3: lambda: round(ax.vel),
        8: lambda: int(ax.reached),
        9: lambda: int(ax.switch("home")),
        10: lambda: int(ax.switch("right")),
        11: lambda: int(ax.switch("left")),
        14: lambda: m.ap[14] if ax.mode == TORQUE else round(ax.delta / (3.14159265 / 512)),
        15: lambda: round((I_RMS_MAX_MA if m.ap[179] == 0 else 1500) * m.ap[6] / 255),
        16: lambda: int(ax.velocity_reached()),
        18: ax.status_word,
        19: lambda: round(ax.torque_current),
        27: lambda: min(round(ax.i2t), params.U32_MAX),
        123: lambda: ax.csf,
        128: lambda: ax.mode,
        129: lambda: int(ax.closed),
        131: lambda: round(ax.measured_v),
        132: lambda: ax.enc_init,
        133: lambda: int(ax.closed and ax.cl_ready),
        150: lambda: round(ax.current_ma * 1.41421356),
        151: lambda: ax.phase_currents()[0],
        152: lambda: ax.phase_currents()[1],
        153: lambda: 100 if ax.faults.undervoltage else round(ax.mech.supply_v * 10),
        154: lambda: round(50 + ax.current_ma * abs(ax.measured_v) / 2_000_000),
        155: lambda: 125 if ax.faults.overtemperature else 35,
        180: lambda: ax.cs_actual,
        196: lambda: m.ap[196],
        198: lambda: int(bool(m.ap[201] & 4)),
        206: lambda: ax.sg,
        207: lambda: int(ax.deviation),
        208: ax.driver_errors,
        209: lambda: P.to_signed(ax.encoder()),
        230: ax.gamma,
        233: lambda: P.to_signed(round(ax.pos / ax.pos_per_pulse())),  # µsteps (T34)
        236: lambda: ax.csf_target,
        237: ax.position_error,
    }
    fn = live.get(n)
    return fn() if fn is not None else m.ap[n]


def write_axis(m: Module, n: int, value: int) -> int:
    """SAP/AAP ``n`` (§6): a status code."""
    p = AXIS.get(n)
    if p is None or not p.writable:
        return P.WRONG_TYPE
    value = params.norm(p, value)
    if not p.valid(value):
        return P.INVALID_VALUE
    ax = m.axis
    if n == 0:
        ax.target = value
        if ax.mode == POSITION:
            ax.move_to(value)
    elif n == 1:
        ax.set_actual(value)
    elif n == 2:
        if ax.mode == VELOCITY:
            ax.vtarget = value
            ax.settled = False
    elif n == 3:
        ax.vel = float(value)
        ax.settled = False
    elif n == 14:
        if not ax.closed:
            return P.INVALID_VALUE  # torque mode needs closed loop (§8.7, decision T4)
        ax.set_torque(value)
    elif n == 19:
        ax.torque_current = float(value)
    elif n == 29:
        ax.i2t_flag = False
    elif n == 128:
        if value == TORQUE and not ax.closed:
            return P.INVALID_VALUE
        if value == TORQUE:
            ax.set_torque(m.ap[14])
        elif value == POSITION:
            ax.move_to(ax.target)
        else:
            ax.rotate(round(ax.vel))
    elif n == 129:
        ax.set_closed_loop(bool(value))
    elif n == 132:
        if value == 1:
            ax.start_encoder_init()
        else:
            ax.enc_init = 0
    elif n == 180:
        ax.cs_actual = value
    elif n == 198:
        m.ap[201] = (m.ap[201] | 4) if value else (m.ap[201] & ~4)
    elif n == 209:
        ax.set_encoder(value)
    else:
        m.ap[n] = value
        ax.settled = False
    if n in (0, 1, 2, 3, 19, 29, 128, 129, 132, 180, 209):
        pass
    return P.OK


def sap(m: Module, c: Command, direct: bool) -> Reply:
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    return Reply(write_axis(m, c.type, c.value), c.value)


def gap(m: Module, c: Command, direct: bool) -> Reply:
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    p = AXIS.get(c.type)
    if p is None or not p.readable:
        return err(P.WRONG_TYPE, c.value)
    return _loaded(m, read_axis(m, c.type), direct)


def stap(m: Module, c: Command, direct: bool) -> Reply:
    """STAP (§5.7.7): the RAM value to the EEPROM; status 5 while locked."""
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    p = AXIS.get(c.type)
    if p is None or not p.storable:
        return err(P.WRONG_TYPE, c.value)
    if m.locked:
        return err(P.EEPROM_LOCKED, c.value)
    m.eeprom.put_axis(c.type, m.ap[c.type])
    return ok(c.value)


def rsap(m: Module, c: Command, direct: bool) -> Reply:
    """RSAP (§5.7.8): the EEPROM value (or the factory default) back into RAM."""
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    p = AXIS.get(c.type)
    if p is None or not p.storable:
        return err(P.WRONG_TYPE, c.value)
    write_axis(m, c.type, m.restore_axis(c.type))
    return ok(c.value)


# ----------------------------------------------------------------- global parameters


def read_global(m: Module, bank: int, n: int) -> int:
    if bank == 0:
        interp = m.interp
        live: dict[int, Callable[[], int]] = {
            128: lambda: interp.state,
            129: lambda: int(interp.download),
            130: lambda: interp.pc,
            132: m.tick_ms,
            133: lambda: m.rng.randrange(0, params.I32_MAX + 1),
        }
        fn = live.get(n)
        return fn() if fn is not None else m.gp0[n]
    if bank == 2:
        return m.user[n]
    return m.bank3[n]


def _global_target(bank: int, n: int) -> tuple[int, Param | None]:
    """The status for a bank/number pair that has no parameter, or the parameter."""
    if bank not in (0, 1, 2, 3):
        return P.INVALID_VALUE, None
    p = params.global_param(bank, n)
    if p is None:
        return P.WRONG_TYPE, None
    return P.OK, p


def write_global(m: Module, bank: int, n: int, value: int) -> int:
    """SGP/AGP (§5.7.9, §10): a status code. Bank 0 parameters 64-127 are stored in the
    EEPROM at once (§10.1)."""
    status, p = _global_target(bank, n)
    if p is None:
        return status
    if not p.writable:
        return P.WRONG_TYPE
    value = params.norm(p, value)
    if not p.valid(value):
        return P.INVALID_VALUE
    if bank == 0:
        if n == 73:
            stored = 1 if value == 1234 else 0
            m.gp0[73] = stored
            m.eeprom.put_global(0, 73, stored)
            return P.OK
        if n in EEPROM_ONLY and m.locked:
            return P.EEPROM_LOCKED
        if n == 132:
            m.tick_base_ns = m.t_ns - (value & 0xFFFFFFFF) * 1_000_000
            return P.OK
        if n == 81 and m.gp0[81] in (1, 3) and value in (0, 2):
            m.program[:] = [None] * MEMORY_SIZE  # §10.1: the program is wiped off
            m.eeprom.put_program([])
        m.gp0[n] = value
        if n == 79:
            m.axis.polarity = value
        if n in EEPROM_ONLY:
            m.eeprom.put_global(0, n, value)
    elif bank == 2:
        m.user[n] = value
    else:
        m.bank3[n] = value
    return P.OK


def sgp(m: Module, c: Command, direct: bool) -> Reply:
    return Reply(write_global(m, c.motor, c.type, c.value), c.value)


def ggp(m: Module, c: Command, direct: bool) -> Reply:
    status, p = _global_target(c.motor, c.type)
    if p is None:
        return err(status, c.value)
    if not p.readable:
        return err(P.WRONG_TYPE, c.value)
    return _loaded(m, read_global(m, c.motor, c.type), direct)


def stgp(m: Module, c: Command, direct: bool) -> Reply:
    """STGP (§5.7.11): user variables #0-#55 and bank 0 to the EEPROM."""
    status, p = _global_target(c.motor, c.type)
    if p is None:
        return err(status, c.value)
    if not p.storable:
        return err(P.WRONG_TYPE, c.value)
    if m.locked and c.type != 73:
        return err(P.EEPROM_LOCKED, c.value)
    m.eeprom.put_global(c.motor, c.type, read_global(m, c.motor, c.type))
    return ok(c.value)


def rsgp(m: Module, c: Command, direct: bool) -> Reply:
    """RSGP (§5.7.12): the stored value back into RAM."""
    status, p = _global_target(c.motor, c.type)
    if p is None:
        return err(status, c.value)
    if not p.storable:
        return err(P.WRONG_TYPE, c.value)
    value = m.restore_global(c.motor, c.type)
    if c.motor == 2:
        m.user[c.type] = value
    else:
        m.gp0[c.type] = value
    return ok(c.value)


# ----------------------------------------------------------------- reference search, I/O


def rfs(m: Module, c: Command, direct: bool) -> Reply:
    """RFS START/STOP/STATUS (§5.7.13). STATUS answers 0 while a search runs (decision
    T11)."""
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    ax = m.axis
    if c.type == 0:
        search = RefSearch(m.ap[193])
        ax.home_search = search
        ax.reached = False
        ax.settled = False
        ax.deviation = False
        return ok(c.value)
    if c.type == 1:
        if isinstance(ax.home_search, RefSearch):
            ax.home_search.abort(ax)
        return ok(c.value)
    if c.type == 2:
        return _loaded(m, 0 if ax.home_search is not None else 1, direct)
    return err(P.WRONG_TYPE, c.value)


def sio(m: Module, c: Command, direct: bool) -> Reply:
    """SIO (§5.7.14): bank 2, OUT_0-OUT_7; type 255 sets all (value -1: accu bits)."""
    if c.motor != 2:
        return err(P.INVALID_VALUE, c.value)
    if c.type == 255:
        if c.value == -1:
            m.outputs = m.interp.accu & 0xFF
        elif 0 <= c.value <= 255:
            m.outputs = c.value
        else:
            return err(P.INVALID_VALUE, c.value)
        return ok(c.value)
    if not 0 <= c.type <= 7:
        return err(P.WRONG_TYPE, c.value)
    if c.value not in (0, 1):
        return err(P.INVALID_VALUE, c.value)
    bit = 1 << c.type
    m.outputs = (m.outputs | bit) if c.value else (m.outputs & ~bit)
    return ok(c.value)


def gio(m: Module, c: Command, direct: bool) -> Reply:
    """GIO (§5.7.15): bank 0 digital inputs, bank 1 analog values, bank 2 outputs."""
    ax = m.axis
    if c.motor == 0:
        if c.type == 255:
            value = sum(m.digital_input(i) << i for i in range(8))
        elif 0 <= c.type <= 7:
            value = m.digital_input(c.type)
        else:
            return err(P.WRONG_TYPE, c.value)
    elif c.motor == 1:
        pa, pb = ax.phase_currents()
        analog: dict[int, Callable[[], int]] = {
            0: lambda: m.analog[0],
            4: lambda: m.analog[1],
            8: lambda: 100 if ax.faults.undervoltage else 240,
            9: lambda: 125 if ax.faults.overtemperature else 35,
            10: lambda: abs(pa),
            11: lambda: abs(pb),
            12: lambda: round(50 + ax.current_ma * abs(ax.measured_v) / 2_000_000),
        }
        fn = analog.get(c.type)
        if fn is None:
            return err(P.WRONG_TYPE, c.value)
        value = fn()
    elif c.motor == 2:
        if c.type == 255:
            value = m.outputs
        elif 0 <= c.type <= 7:
            value = (m.outputs >> c.type) & 1
        else:
            return err(P.WRONG_TYPE, c.value)
    else:
        return err(P.INVALID_VALUE, c.value)
    return _loaded(m, value, direct)


# ----------------------------------------------------------------- coordinates (§5.7.24-27)


def _coord_store(m: Module, n: int, value: int) -> None:
    m.coords[n] = value
    if m.gp0[84] and n > 0:
        m.eeprom.put_coord(n, value)


def sco(m: Module, c: Command, direct: bool) -> Reply:
    """SCO n, 0, pos stores a coordinate; SCO n, 255 copies RAM to EEPROM (all with n=0;
    decision T12)."""
    if not 0 <= c.type < len(m.coords):
        return err(P.WRONG_TYPE, c.value)
    if c.motor == 255:
        for n in range(1, len(m.coords)) if c.type == 0 else (c.type,):
            m.eeprom.put_coord(n, m.coords[n])
        return ok(c.value)
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    _coord_store(m, c.type, c.value)
    return ok(c.value)


def gco(m: Module, c: Command, direct: bool) -> Reply:
    """GCO (§5.7.25); GCO n, 255 copies EEPROM to RAM (all but 0 with n=0)."""
    if not 0 <= c.type < len(m.coords):
        return err(P.WRONG_TYPE, c.value)
    if c.motor == 255:
        stored = m.eeprom.coords()
        for n in range(1, len(m.coords)) if c.type == 0 else (c.type,):
            m.coords[n] = stored.get(n, 0)
        return ok(c.value)
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    return _loaded(m, m.coords[c.type], direct)


def cco(m: Module, c: Command, direct: bool) -> Reply:
    if not 0 <= c.type < len(m.coords):
        return err(P.WRONG_TYPE, c.value)
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    _coord_store(m, c.type, m.axis.actual())
    return ok(c.value)


def aco(m: Module, c: Command, direct: bool) -> Reply:
    if not 0 <= c.type < len(m.coords):
        return err(P.WRONG_TYPE, c.value)
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    _coord_store(m, c.type, m.interp.accu)
    return ok(c.value)


# ----------------------------------------------------------------- calculation (§5.7.16-30)


def _arith(op: int, a: int, b: int) -> int | None:
    if op == 0:
        return a + b
    if op == 1:
        return a - b
    if op == 2:
        return a * b
    if op in (3, 4):
        if b == 0:
            return None
        q = abs(a) // abs(b) * (1 if (a < 0) == (b < 0) else -1)  # C division
        return q if op == 3 else a - q * b
    if op == 5:
        return a & b
    if op == 6:
        return a | b
    if op == 7:
        return a ^ b
    if op == 8:
        return ~a
    return b  # LOAD


def calc(m: Module, c: Command, direct: bool) -> Reply:
    if not 0 <= c.type <= 9:
        return err(P.WRONG_TYPE, c.value)
    result = _arith(c.type, m.interp.accu, c.value)
    if result is None:
        return err(P.INVALID_VALUE, c.value)
    m.interp.load(result)
    return ok(c.value)


def calcx(m: Module, c: Command, direct: bool) -> Reply:
    """CALCX (§5.7.28): LOAD copies the accumulator to X, SWAP exchanges them."""
    it = m.interp
    if c.type == 9:
        it.x = it.accu
        return ok(c.value)
    if c.type == 10:
        it.accu, it.x = it.x, it.accu
        return ok(c.value)
    if not 0 <= c.type <= 8:
        return err(P.WRONG_TYPE, c.value)
    result = _arith(c.type, it.accu, it.x)
    if result is None:
        return err(P.INVALID_VALUE, c.value)
    it.load(result)
    return ok(c.value)


def comp(m: Module, c: Command, direct: bool) -> Reply:
    m.interp.compare(c.value)
    return ok(c.value)


def aap(m: Module, c: Command, direct: bool) -> Reply:
    if c.motor != 0:
        return err(P.INVALID_VALUE, c.value)
    return Reply(write_axis(m, c.type, m.interp.accu), c.value)


def agp(m: Module, c: Command, direct: bool) -> Reply:
    return Reply(write_global(m, c.motor, c.type, m.interp.accu), c.value)


def cle(m: Module, c: Command, direct: bool) -> Reply:
    """CLE ALL/ETO/EDV (§5.7.31)."""
    if c.type not in (0, 1, 3):
        return err(P.WRONG_TYPE, c.value)
    if c.type in (0, 1):
        m.interp.eto = False
    if c.type in (0, 3):
        m.axis.deviation = False
    return ok(c.value)


# ----------------------------------------------------------------- interrupts (§5.6)


def vect(m: Module, c: Command, direct: bool) -> Reply:
    if c.type not in INTERRUPTS:
        return err(P.WRONG_TYPE, c.value)
    if not 0 <= c.value < MEMORY_SIZE:
        return err(P.INVALID_VALUE, c.value)
    m.interp.vectors[c.type] = c.value
    return ok(c.value)


def ei(m: Module, c: Command, direct: bool) -> Reply:
    if c.type == GLOBAL_IRQ:
        m.interp.global_enabled = True
    elif c.type in INTERRUPTS:
        m.interp.enabled.add(c.type)
    else:
        return err(P.WRONG_TYPE, c.value)
    return ok(c.value)


def di(m: Module, c: Command, direct: bool) -> Reply:
    if c.type == GLOBAL_IRQ:
        m.interp.global_enabled = False
    elif c.type in INTERRUPTS:
        m.interp.enabled.discard(c.type)
        m.interp.pending.discard(c.type)
    else:
        return err(P.WRONG_TYPE, c.value)
    return ok(c.value)


def user_function(m: Module, c: Command, direct: bool) -> Reply:
    """UF0-UF7 (§5.7.36): no customer extension in this firmware; answered, no effect."""
    return ok(c.value)


# ----------------------------------------------------------------- control functions


def control(m: Module, c: Command, direct: bool) -> Reply | None:
    """Commands 128-139 (§4.3, §5.7.37, §5.7.39, §4.4)."""
    it = m.interp
    op = c.opcode
    if op == P.STOP_APP:
        it.stop()
    elif op == P.RUN_APP:
        if c.type == 1 and not 0 <= c.value < MEMORY_SIZE:
            return err(P.INVALID_VALUE, c.value)
        it.run(c.value if c.type == 1 else None)
    elif op == P.STEP_APP:
        it.step()
    elif op == P.RESET_APP:
        it.reset()
    elif op == P.DOWNLOAD_START:
        if not 0 <= c.value < MEMORY_SIZE:
            return err(P.INVALID_VALUE, c.value)
        if m.gp0[81] in (2, 3):
            return err(P.EEPROM_LOCKED, c.value)  # protected against overwriting
        it.start_download(c.value)
    elif op == P.DOWNLOAD_END:
        if it.download:
            it.end_download()
    elif op == P.READ_MEMORY:
        return read_memory(m, c)
    elif op == P.APP_STATUS:
        return ok(it.state)
    elif op == P.FIRMWARE_VERSION:
        if c.type == 0:
            from ecatsim.tmcl.module import VERSION

            return Reply(P.OK, 0, raw=P.version_reply(m.host_address, VERSION))
        if c.type == 1:
            from ecatsim.tmcl.module import VERSION_BINARY

            return ok(VERSION_BINARY)
        return err(P.WRONG_TYPE, c.value)
    elif op == P.FACTORY_DEFAULTS:
        if c.value != 1234:
            return err(P.INVALID_VALUE, c.value)
        m.eeprom.clear()
        m.power_up()
        return None
    elif op == P.TARGET_EVENT:
        if c.value != 0:
            return err(P.INVALID_VALUE, c.value)
        m.target_event = True
        return ok(1)
    elif op == P.ASCII_MODE:
        return ok(c.value)  # the line switches after this reply (server.py)
    else:
        return err(P.INVALID_COMMAND, c.value)
    return ok(c.value)


def read_memory(m: Module, c: Command) -> Reply:
    """Command 134: the instruction at ``value`` in the seven command bytes after the host
    address, with a checksum (decision T17); protected programs read as zeros."""
    if not 0 <= c.value < MEMORY_SIZE:
        return err(P.INVALID_VALUE, c.value)
    cmd = m.program[c.value]
    if cmd is None or m.gp0[81] in (1, 3):
        cmd = Command(0)
    body = bytes([m.host_address]) + cmd.pack()
    return Reply(P.OK, 0, raw=body + bytes([P.checksum(body)]))


def _program_only(m: Module, c: Command, direct: bool) -> Reply:
    return err(P.NOT_AVAILABLE, c.value)


HANDLERS: dict[int, Handler] = {
    P.ROR: ror,
    P.ROL: rol,
    P.MST: mst,
    P.MVP: mvp,
    P.SAP: sap,
    P.GAP: gap,
    P.STAP: stap,
    P.RSAP: rsap,
    P.SGP: sgp,
    P.GGP: ggp,
    P.STGP: stgp,
    P.RSGP: rsgp,
    P.RFS: rfs,
    P.SIO: sio,
    P.GIO: gio,
    P.CALC: calc,
    P.COMP: comp,
    P.EI: ei,
    P.DI: di,
    P.SCO: sco,
    P.GCO: gco,
    P.CCO: cco,
    P.CALCX: calcx,
    P.AAP: aap,
    P.AGP: agp,
    P.CLE: cle,
    P.VECT: vect,
    P.ACO: aco,
    **{op: _program_only for op in PROGRAM_ONLY},
    **{op: user_function for op in range(P.UF0, P.UF7 + 1)},
    **{op: control for op in range(P.STOP_APP, P.ASCII_MODE + 1)},
}


def execute(m: Module, c: Command, direct: bool) -> Reply | None:
    """One command from the host (``direct``) or from the program."""
    if direct and m.interp.download and not P.STOP_APP <= c.opcode <= P.ASCII_MODE:
        if m.interp.dl_ptr >= MEMORY_SIZE:
            return err(P.INVALID_VALUE, c.value)
        return Reply(P.LOADED, m.interp.store(c))
    handler = HANDLERS.get(c.opcode)
    if handler is None:
        return err(P.INVALID_COMMAND, c.value)
    return handler(m, c, direct)


__all__ = ["BANK0", "HANDLERS", "USER_VARS_STORED", "execute", "read_axis", "read_global"]
