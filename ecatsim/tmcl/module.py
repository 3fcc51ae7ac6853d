"""One emulated TMCM-1311: parameter RAM, configuration EEPROM, I/O, coordinates, the axis
and the TMCL interpreter, advanced on the simulated time it is given.

Ref: TMCM-1311 TMCL firmware manual §4 (TMCL), §5.7 (commands), §6 and §10 (parameters).
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

from ecatsim.tmcl import params
from ecatsim.tmcl.eeprom import Section
from ecatsim.tmcl.motor import Axis, Mechanics, Switches
from ecatsim.tmcl.params import AXIS, BANK0, BANK3, USER_VARS, USER_VARS_STORED
from ecatsim.tmcl.program import MEMORY_SIZE, Interpreter
from ecatsim.tmcl.protocol import Command, Reply

#: the string command 136 type 0 answers (§5.7.39): module 1311, firmware V1.11
VERSION = "1311V111"
#: command 136 type 1: bytes 05 1F (module type 1311), version low byte, high byte
VERSION_BINARY = 0x051F0B01
#: the magic global parameter 64 must hold for the EEPROM to count at power-up (§10.1)
EEPROM_MAGIC = 0xE4
#: analog input scale: 12 bits over 0-10 V (§5.7.15)
ADC_MAX = 4095
#: number of coordinates (§5.7.24-5.7.27)
COORDS = 21


@dataclass(slots=True)
class ModuleConfig:
    """What a segment YAML or the command line says about one module."""

    address: int = 1
    mech: Mechanics = field(default_factory=Mechanics)
    switches: Switches = field(default_factory=Switches)
    #: analog inputs AIN0 and AIN4, 0-4095
    analog: tuple[int, int] = (0, 0)
    seed: int = 1311


class Module:
    """One TMCM-1311 on the line."""

    def __init__(self, index: int, cfg: ModuleConfig, eeprom: Section, now_ns: int) -> None:
        self.index = index
        self.cfg = cfg
        self.eeprom = eeprom
        self.ap: dict[int, int] = {}
        self.gp0: dict[int, int] = {}
        self.user = [0] * USER_VARS
        self.bank3: dict[int, int] = {}
        self.coords = [0] * COORDS
        self.program: list[Command | None] = [None] * MEMORY_SIZE
        self.inputs = [0] * 8
        self.analog = list(cfg.analog)
        self.outputs = 0
        self.rng = random.Random(cfg.seed)
        self.axis = Axis(self.ap, cfg.mech, cfg.switches)
        self.interp = Interpreter(self)
        self.t_ns = now_ns
        self.tick_base_ns = now_ns
        #: the address the default config gives when the EEPROM holds none
        self._default_address = cfg.address
        #: replies a command 138 still owes: sent when the target is reached
        self.target_event = False
        self.last_command_ns = now_ns
        self.heartbeat_stopped = False
        self.commands = 0
        self.errors = 0
        self.power_up()

    # ------------------------------------------------------------- power-up

    def power_up(self) -> None:
        """Factory defaults, then what the EEPROM holds (§6 access E, §10)."""
        stored_globals = self.eeprom.globals()
        if stored_globals.get((0, 64), EEPROM_MAGIC) != EEPROM_MAGIC:
            self.eeprom.clear()
            stored_globals = {}
        self.ap.clear()
        self.ap.update({n: p.default for n, p in AXIS.items()})
        self.gp0 = {n: p.default for n, p in BANK0.items()}
        self.gp0[66] = self._default_address
        self.bank3 = {n: p.default for n, p in BANK3.items()}
        self.user = [0] * USER_VARS
        self.coords = [0] * COORDS
        for n, v in self.eeprom.axis().items():
            if n in AXIS and AXIS[n].storable:
                self.ap[n] = v
        for (bank, n), v in stored_globals.items():
            if bank == 0 and n in BANK0:
                self.gp0[n] = v
        if self.gp0[85] == 0:
            for (bank, n), v in stored_globals.items():
                if bank == 2 and 0 <= n < USER_VARS_STORED:
                    self.user[n] = v
        if self.gp0[84]:
            for n, v in self.eeprom.coords().items():
                if 1 <= n < COORDS:
                    self.coords[n] = v
        self.program = [None] * MEMORY_SIZE
        for i, (op, typ, motor, value) in enumerate(self.eeprom.program()[:MEMORY_SIZE]):
            self.program[i] = Command(op, typ, motor, value)
        self.axis = Axis(self.ap, self.cfg.mech, self.cfg.switches, self.gp0[79])
        self.axis.t_ns = self.t_ns
        self.interp = Interpreter(self)
        self.tick_base_ns = self.t_ns
        self.target_event = False
        if self.gp0[77]:
            self.interp.run(0)

    # ------------------------------------------------------------- addressing

    @property
    def address(self) -> int:
        """Global parameter 66 (§10.1)."""
        return self.gp0[66]

    @property
    def host_address(self) -> int:
        """Global parameter 76 (§10.1): the reply address."""
        return self.gp0[76]

    @property
    def locked(self) -> bool:
        """Global parameter 73 (§10.1): the configuration EEPROM is locked."""
        return self.gp0[73] == 1

    # ------------------------------------------------------------- time

    def advance_to(self, t_ns: int) -> None:
        """Move the axis and run the program up to ``t_ns``."""
        if t_ns <= self.t_ns:
            return
        hb = self.gp0[68]
        if hb and not self.heartbeat_stopped:  # §10.1: the serial heartbeat
            due = self.last_command_ns + hb * 1_000_000
            if due <= t_ns:
                self._advance(due)
                self.axis.stop()
                self.heartbeat_stopped = True
        self._advance(t_ns)

    def _advance(self, t_ns: int) -> None:
        if t_ns <= self.t_ns:
            return
        if not self.interp.active():
            self.axis.advance_to(t_ns)
            self._events()
            self.t_ns = t_ns
            return
        while self.t_ns < t_ns:  # interleave: 1 ms of motion, then the program's time
            chunk = min(t_ns, self.t_ns + 1_000_000)
            self.axis.advance_to(chunk)
            self._events()
            self.interp.run_until(chunk)
            self.t_ns = chunk

    def _events(self) -> None:
        """Axis edges to interrupts (§5.6) and the owed reply of command 138."""
        for ev in self.axis.events:
            self.interp.axis_event(ev)
        self.axis.events.clear()

    def tick_ms(self) -> int:
        """Global parameter 132: a millisecond counter (§10.1)."""
        return ((self.t_ns - self.tick_base_ns) // 1_000_000) & 0xFFFFFFFF

    def next_deadline(self) -> int | None:
        """When the module needs time to pass while nobody asks (motion, a program, a 138
        reply owed, the heartbeat)."""
        ax = self.axis
        busy = not ax.settled or self.interp.active() or self.target_event
        if busy:
            return self.t_ns + 5_000_000
        if self.gp0[68] and not self.heartbeat_stopped:
            return self.last_command_ns + self.gp0[68] * 1_000_000
        return None

    # ------------------------------------------------------------- I/O

    def digital_input(self, port: int) -> int:
        """Bank 0 (§5.7.15.1): AIN0/AIN4 read as digital above half scale; IN1 carries the
        reference (home) switch when the config fits one (decision T10)."""
        if port in (0, 4):
            return int(self.analog[port // 4] > ADC_MAX // 2)
        if port == 1 and self.cfg.switches.home is not None:
            return int(self.axis.switch("home"))
        return self.inputs[port]

    def set_input(self, port: int, level: int) -> None:
        """A digital input changes (``ctl``); edges go to the input interrupts."""
        old = self.digital_input(port)
        self.inputs[port] = 1 if level else 0
        new = self.digital_input(port)
        if new != old:
            self.interp.input_edge(port, bool(new))

    # ------------------------------------------------------------- parameters

    def restore_axis(self, number: int) -> int:
        """What RSAP copies back: the stored value or the factory default."""
        return self.eeprom.axis().get(number, AXIS[number].default)

    def restore_global(self, bank: int, number: int) -> int:
        p = params.global_param(bank, number)
        default = p.default if p is not None else 0
        if bank == 0 and number == 66:
            default = self._default_address
        return self.eeprom.globals().get((bank, number), default)

    def execute(self, cmd: Command, direct: bool = True) -> Reply | None:
        """Execute one command; None where the module sends no reply (137)."""
        from ecatsim.tmcl.commands import execute

        if direct:
            self.commands += 1
            self.last_command_ns = self.t_ns
            self.heartbeat_stopped = False
        reply = execute(self, cmd, direct)
        if reply is not None and reply.status < 100:
            self.errors += 1
        return reply
