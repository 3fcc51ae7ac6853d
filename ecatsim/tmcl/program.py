"""Standalone TMCL programs: program memory, download mode, the interpreter with its
accumulator, X register, flags, subroutine stack, WAIT, and interrupts.

The interpreter runs on simulated time: each instruction takes :data:`INSTR_NS` (decision
T15), a WAIT holds the program counter until its condition or timeout, interrupts are taken
between instructions.

Ref: TMCM-1311 TMCL firmware manual §4.3 (standalone applications), §5.3 (control
commands), §5.5 (accumulator and X register), §5.6 (interrupts), §5.7.16-5.7.23, §5.7.28,
§5.7.32-5.7.35, §10.1 (parameters 77, 128-130), §10.4 (bank 3), §11.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.protocol import Command

if TYPE_CHECKING:
    from ecatsim.tmcl.module import Module

#: program memory in instructions (§4: "up to 2048 TMCL instructions", decision T14)
MEMORY_SIZE = 2048
#: the time one instruction takes
INSTR_NS = 20_000
#: one WAIT tick (§5.7.22)
TICK_NS = 10_000_000
#: subroutine nesting (§5.7.20)
STACK_DEPTH = 8

# application status (global parameter 128, command 135)
STOPPED, RUNNING, STEPPING, RESET = 0, 1, 2, 3

#: the interrupt vectors (§5.6.3)
INTERRUPTS = (0, 1, 2, 3, 15, 21, 27, 28, *range(39, 47))
GLOBAL_IRQ = 255
TIMERS = (0, 1, 2)

#: instructions only a program can execute
PROGRAM_ONLY = (P.JC, P.JA, P.CSUB, P.RSUB, P.WAIT, P.STOP, P.RETI)


@dataclass(slots=True)
class Wait:
    kind: int
    #: the end of a WAIT TICKS or the timeout of the others (None: no timeout)
    until_ns: int | None


@dataclass(slots=True)
class Context:
    """What an interrupt saves and RETI restores (§5.6.2)."""

    pc: int
    accu: int
    x: int
    cmp: int
    wait: Wait | None


class Interpreter:
    """The TMCL interpreter of one module."""

    def __init__(self, module: Module) -> None:
        self.m = module
        self.state = STOPPED
        self.pc = 0
        self.stack: list[int] = []
        self.accu = 0
        self.x = 0
        #: sign of the last comparison (accu - operand), -1/0/1
        self.cmp = 0
        self.eto = False
        self.wait: Wait | None = None
        self.next_ns = 0
        # download mode (§4.3, commands 132/133)
        self.download = False
        self.dl_ptr = 0
        # interrupts (§5.6)
        self.vectors: dict[int, int] = {}
        self.enabled: set[int] = set()
        self.global_enabled = False
        self.pending: set[int] = set()
        self.isr: Context | None = None
        self.timer_next: dict[int, int] = {}
        self.executed = 0

    # ------------------------------------------------------------- control (128-135)

    def active(self) -> bool:
        return self.state == RUNNING

    def run(self, address: int | None) -> None:
        """Command 129: run from ``address`` or from the current program counter. What the
        program set up stays (a program stopped by 128 goes on where it was); the timers
        count their periods from the start (decision T29)."""
        if address is not None:
            self.pc = address
        elif self.state == RESET:
            self.pc = 0
        self.state = RUNNING
        self.wait = None
        self.next_ns = self.m.t_ns
        self.timer_next.clear()

    def stop(self) -> None:
        """Command 128 and STOP: instruction fetching stops (§5.7.23)."""
        self.state = STOPPED
        self.wait = None

    def reset(self) -> None:
        """Command 131: stopped, program counter, stack, registers, interrupt vectors,
        enables and timers reset (decision T29); bank 3 keeps its settings."""
        self.state = RESET
        self.pc = 0
        self.stack.clear()
        self.accu = self.x = self.cmp = 0
        self.eto = False
        self.wait = None
        self.isr = None
        self.vectors.clear()
        self.enabled.clear()
        self.global_enabled = False
        self.pending.clear()
        self.timer_next.clear()

    def step(self) -> None:
        """Command 130: execute one instruction."""
        self.state = STEPPING
        self.wait = None
        self._execute_one(self.m.t_ns)
        if self.wait is not None:  # a stepped WAIT is done at once (decision T15)
            self.wait = None
            self.pc += 1

    def start_download(self, address: int) -> None:
        """Command 132: the program is replaced, so it is stopped and reset as by 131: no
        vector, enable or timer of the old code stays armed; the status reads stopped
        (decision T29)."""
        self.reset()
        self.state = STOPPED
        self.download = True
        self.dl_ptr = address

    def store(self, cmd: Command) -> int:
        """In download mode: the command goes to program memory (§4.3); the address."""
        addr = self.dl_ptr
        self.m.program[addr] = cmd
        self.dl_ptr = addr + 1
        return addr

    def end_download(self) -> None:
        self.download = False
        words = [
            (c.opcode, c.type, c.motor, c.value) if c is not None else (0, 0, 0, 0)
            for c in self.m.program
        ]
        while words and words[-1] == (0, 0, 0, 0):
            words.pop()
        self.m.eeprom.put_program(words)

    # ------------------------------------------------------------- interrupts

    def _raise(self, number: int) -> None:
        if self.state == RUNNING and number in self.enabled:
            self.pending.add(number)

    def axis_event(self, event: str) -> None:
        """An axis edge (target reached, stall, deviation, stop switches, §5.6.3)."""
        if event == "reached":
            self._raise(3)
            return
        if event == "stall":
            self._raise(15)
            return
        if event == "deviation":
            self._raise(21)
            return
        name, edge = event[:-1], event[-1]
        number = {"left": 27, "right": 28}.get(name)
        if number is not None and self._edge_matches(self.m.bank3[number], edge == "+"):
            self._raise(number)

    def input_edge(self, port: int, rising: bool) -> None:
        """Input change interrupts 39-46 with the edge type of bank 3 (§10.4)."""
        if self._edge_matches(self.m.bank3[39 + port], rising):
            self._raise(39 + port)

    @staticmethod
    def _edge_matches(kind: int, rising: bool) -> bool:
        return kind == 3 or (kind == 1 and rising) or (kind == 2 and not rising)

    def _timers(self, now: int) -> None:
        for t in TIMERS:
            period = self.m.bank3[t]
            if period == 0 or t not in self.enabled:
                self.timer_next.pop(t, None)
                continue
            nxt = self.timer_next.get(t)
            if nxt is None:
                self.timer_next[t] = now + period * 1_000_000
            elif now >= nxt:
                self.pending.add(t)
                span = period * 1_000_000
                self.timer_next[t] = nxt + span * ((now - nxt) // span + 1)

    def _take_interrupt(self) -> bool:
        if not self.global_enabled or self.isr is not None or not self.pending:
            return False
        for n in sorted(self.pending):
            self.pending.discard(n)
            if n in self.enabled and n in self.vectors:
                self.isr = Context(self.pc, self.accu, self.x, self.cmp, self.wait)
                self.wait = None
                self.pc = self.vectors[n]
                return True
        return False

    # ------------------------------------------------------------- running

    def run_until(self, t_ns: int) -> None:
        """Execute what the program can do by ``t_ns``."""
        while self.state == RUNNING:
            now = max(self.next_ns, self.m.t_ns)
            if now > t_ns:
                return
            self._timers(now)
            self._take_interrupt()
            if self.wait is not None and not self._wait_over(now, t_ns):
                return
            self._execute_one(now)
            self.next_ns = now + INSTR_NS

    def _wait_over(self, now: int, t_ns: int) -> bool:
        """The WAIT's condition holds at ``t_ns`` (checked once per millisecond of motion)."""
        w = self.wait
        assert w is not None
        if w.kind == 0:
            assert w.until_ns is not None
            if w.until_ns > t_ns:
                return False
            self.next_ns = w.until_ns
        else:
            if not self._condition(w.kind):
                if w.until_ns is not None and w.until_ns <= t_ns:
                    self.eto = True
                    self.next_ns = w.until_ns
                else:
                    return False
        self.wait = None
        self.pc += 1
        return True

    def _condition(self, kind: int) -> bool:
        ax = self.m.axis
        if kind == 1:
            return ax.reached
        if kind == 2:
            return ax.switch("home")
        if kind == 3:
            return ax.switch("left") or ax.switch("right")
        return ax.home_search is None

    def _execute_one(self, now: int) -> None:
        if not 0 <= self.pc < MEMORY_SIZE or self.m.program[self.pc] is None:
            self.stop()
            return
        cmd = self.m.program[self.pc]
        assert cmd is not None
        self.executed += 1
        if self.wait is not None:  # a WAIT resumed after an interrupt: keep waiting
            return
        op = cmd.opcode
        pc = self.pc
        self.pc = pc + 1
        if op == P.JA:
            self.pc = cmd.value
        elif op == P.JC:
            if self._jump_condition(cmd.type):
                self.pc = cmd.value
        elif op == P.CSUB:
            if len(self.stack) < STACK_DEPTH:
                self.stack.append(pc + 1)
                self.pc = cmd.value
        elif op == P.RSUB:
            if self.stack:
                self.pc = self.stack.pop()
        elif op == P.WAIT:
            self.pc = pc
            ticks = cmd.value * TICK_NS
            if cmd.type == 0:
                self.wait = Wait(0, now + ticks)
            else:
                self.wait = Wait(cmd.type, now + ticks if cmd.value > 0 else None)
        elif op == P.STOP:
            self.pc = pc
            self.stop()
        elif op == P.RETI:
            if self.isr is not None:
                ctx = self.isr
                self.isr = None
                self.pc, self.accu, self.x, self.cmp, self.wait = (
                    ctx.pc,
                    ctx.accu,
                    ctx.x,
                    ctx.cmp,
                    ctx.wait,
                )
        else:
            self.m.execute(cmd, direct=False)

    def _jump_condition(self, cond: int) -> bool:
        """JC conditions (§5.7.18) on the last comparison or accumulator load."""
        c = self.cmp
        return {
            0: c == 0,
            1: c != 0,
            2: c == 0,
            3: c != 0,
            4: c > 0,
            5: c >= 0,
            6: c < 0,
            7: c <= 0,
            8: self.eto,
        }.get(cond, False)

    def load(self, value: int) -> None:
        """An instruction that reads a value puts it into the accumulator (§5.5); the
        flags then compare it with zero (decision T16)."""
        self.accu = P.to_signed(value)
        self.cmp = (self.accu > 0) - (self.accu < 0)

    def compare(self, value: int) -> None:
        """COMP (§5.7.17)."""
        self.cmp = (self.accu > value) - (self.accu < value)
