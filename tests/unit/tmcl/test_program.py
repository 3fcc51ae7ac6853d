"""Standalone programs: download mode, run/stop/step, the interpreter, interrupts.

Ref: TMCM-1311 TMCL firmware manual §4.3, §5.3, §5.5, §5.6, §5.7.16-5.7.23, §10.1, §10.4.
"""

from __future__ import annotations

from ecatsim.tmcl import protocol as P
from tests.unit.tmcl.conftest import Bench

#: §5.6.5's example: VECT 0, Irq / SGP 0, 3, 100 / EI 0 / EI 255 / Loop: WAIT TICKS 0, 50 /
#: JA Loop; Irq: GGP 20, 2 / CALC ADD, 1 / AGP 20, 2 / RETI (a timer interrupt every 100 ms)
TIMER_PROGRAM = [
    (P.VECT, 0, 0, 6),
    (P.SGP, 0, 3, 100),
    (P.EI, 0, 0, 0),
    (P.EI, 255, 0, 0),
    (P.WAIT, 0, 0, 50),
    (P.JA, 0, 0, 4),
    (P.GGP, 20, 2, 0),
    (P.CALC, 0, 0, 1),
    (P.AGP, 20, 2, 0),
    (P.RETI, 0, 0, 0),
]


def download(bench: Bench, program: list[tuple[int, int, int, int]], at: int = 0) -> None:
    assert bench.cmd(P.DOWNLOAD_START, 0, 0, at)[0] == P.OK
    assert bench.m.interp.download  # GGP 129 would be stored now, not answered
    for i, (op, typ, motor, value) in enumerate(program):
        assert bench.cmd(op, typ, motor, value) == (P.LOADED, at + i)
    assert bench.cmd(P.DOWNLOAD_END)[0] == P.OK
    assert bench.value(P.GGP, 129) == 0


def test_download_run_stop_step_change_what_ggp_and_gap_read(bench: Bench) -> None:
    # Loop: GGP 0, 2 / CALC ADD, 1 / AGP 0, 2 / AAP 4, 0 / WAIT TICKS, 0, 1 / JA Loop
    download(
        bench,
        [
            (P.GGP, 0, 2, 0),
            (P.CALC, 0, 0, 1),
            (P.AGP, 0, 2, 0),
            (P.AAP, 4, 0, 0),
            (P.WAIT, 0, 0, 1),
            (P.JA, 0, 0, 0),
        ],
    )
    assert bench.send(P.encode_command(1, P.Command(P.READ_MEMORY, 0, 0, 1))) == bytes(
        [2, P.CALC, 0, 0, 0, 0, 0, 1, (2 + P.CALC + 1) & 0xFF]
    )
    assert bench.value(P.APP_STATUS) == 0
    bench.value(P.RUN_APP, 0, 0, 0)
    assert bench.value(P.APP_STATUS) == 1
    bench.advance(0.105)  # ten and a half WAIT ticks of 10 ms
    n = bench.value(P.GGP, 0, 2)
    assert n in (10, 11)
    assert bench.gap(4) == n
    assert bench.value(P.STOP_APP) == 0
    assert bench.value(P.GGP, 128) == 0
    bench.advance(0.5)
    assert bench.value(P.GGP, 0, 2) == n  # stopped: nothing changes
    # a direct GGP does not touch the program's accumulator (§5.5)
    pc = bench.value(P.GGP, 130)
    for _ in range(6):
        bench.value(P.STEP_APP)
    assert bench.value(P.GGP, 0, 2) == n + 1
    assert bench.value(P.GGP, 128) == 2
    assert bench.value(P.GGP, 130) == pc
    bench.value(P.RESET_APP)
    assert bench.value(P.GGP, 130) == 0


def test_program_memory_survives_a_restart_and_autostarts() -> None:
    from pathlib import Path
    from tempfile import TemporaryDirectory

    from ecatsim.clock import ManualClock
    from ecatsim.tmcl.module import ModuleConfig
    from ecatsim.tmcl.server import TmclDoor

    with TemporaryDirectory() as d:
        path = Path(d) / "e.json"
        door = TmclDoor([ModuleConfig()], [], path, clock=ManualClock())
        m = door.modules[0]
        for c in (
            P.Command(P.DOWNLOAD_START, 0, 0, 0),
            P.Command(P.SGP, 7, 2, 4711),
            P.Command(P.STOP),
            P.Command(P.DOWNLOAD_END),
            P.Command(P.SGP, 77, 0, 1),
        ):
            m.execute(c)
        door.close()
        door = TmclDoor([ModuleConfig()], [], path, clock=ManualClock())
        m = door.modules[0]
        door.service(1_000_000)
        assert m.user[7] == 4711  # global parameter 77: the program ran at power-up
        assert m.interp.state == 0  # and ended with STOP
        door.close()


def test_subroutines_compare_and_conditional_jumps(bench: Bench) -> None:
    download(
        bench,
        [
            (P.CALC, 9, 0, 5),  # 0 LOAD 5
            (P.CSUB, 0, 0, 6),  # 1
            (P.COMP, 0, 0, 10),  # 2
            (P.JC, 6, 0, 1),  # 3 LT -> 1
            (P.AGP, 1, 2, 0),  # 4
            (P.STOP, 0, 0, 0),  # 5
            (P.CALC, 0, 0, 2),  # 6 ADD 2
            (P.RSUB, 0, 0, 0),  # 7
        ],
    )
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.01)
    assert bench.value(P.GGP, 1, 2) == 11
    assert bench.value(P.APP_STATUS) == 0


def test_wait_pos_with_timeout_sets_eto(bench: Bench) -> None:
    download(
        bench,
        [
            (P.MVP, 0, 0, 1_000_000),  # far away
            (P.WAIT, 1, 0, 5),  # 50 ms timeout
            (P.JC, 8, 0, 4),  # ETO -> 4
            (P.STOP, 0, 0, 0),
            (P.SGP, 9, 2, 1),
            (P.CLE, 1, 0, 0),
            (P.STOP, 0, 0, 0),
        ],
    )
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.04)
    assert bench.value(P.GGP, 9, 2) == 0
    bench.advance(0.02)
    assert bench.value(P.GGP, 9, 2) == 1
    assert bench.m.interp.eto is False


def test_timer_interrupt_handler_fires_on_its_period(bench: Bench) -> None:
    download(bench, TIMER_PROGRAM)
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.95)
    assert bench.value(P.GGP, 20, 2) == 9  # at 100, 200, ... 900 ms
    bench.advance(0.1)
    assert bench.value(P.GGP, 20, 2) == 10
    bench.value(P.DI, 255)
    bench.advance(0.5)
    assert bench.value(P.GGP, 20, 2) == 10


def test_target_reached_interrupt_and_input_change_interrupt(bench: Bench) -> None:
    bench.sap(5, 1_000_000)
    bench.sap(4, 100_000)

    def counter(var: int) -> list[tuple[int, int, int, int]]:
        """GGP var, 2 / CALC ADD, 1 / AGP var, 2 / RETI"""
        return [(P.GGP, var, 2, 0), (P.CALC, 0, 0, 1), (P.AGP, var, 2, 0), (P.RETI, 0, 0, 0)]

    download(
        bench,
        [
            (P.VECT, 3, 0, 8),
            (P.VECT, 40, 0, 12),
            (P.SGP, 40, 3, 1),  # input 1: rising edges only (bank 3, §10.4)
            (P.EI, 3, 0, 0),
            (P.EI, 40, 0, 0),
            (P.EI, 255, 0, 0),
            (P.JA, 0, 0, 6),  # 6: the main loop
            (P.STOP, 0, 0, 0),
            *counter(30),  # 8: target reached
            *counter(31),  # 12: input 1 rose
        ],
    )
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.01)
    bench.value(P.MVP, 0, 0, 10_000)
    bench.advance(0.5)
    assert bench.value(P.GGP, 30, 2) == 1
    bench.value(P.MVP, 0, 0, 0)
    bench.advance(0.5)
    assert bench.value(P.GGP, 30, 2) == 2
    for level in (1, 0, 1):
        bench.m.set_input(1, level)
        bench.advance(0.01)
    assert bench.value(P.GGP, 31, 2) == 2


def test_direct_mode_is_answered_while_a_program_runs(bench: Bench) -> None:
    download(bench, [(P.WAIT, 0, 0, 1000), (P.STOP, 0, 0, 0)])
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.05)
    assert bench.gap(4) == 51200
    assert bench.m.interp.accu == 0
    assert bench.value(P.GGP, 128) == 1


def test_a_new_download_disarms_the_old_programs_interrupts_and_timers(bench: Bench) -> None:
    """Decision T29: 132 replaces the program, so it resets the interpreter as 131 does
    (vectors, enables, global enable, timers); 129 then starts the new code alone. Bank 3
    (the timer period) is a parameter and stays."""
    download(bench, TIMER_PROGRAM)  # cell 6: the timer's handler counts in variable 20
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.35)
    assert bench.value(P.GGP, 20, 2) == 3
    # the new program: a loop counting in variable 21; its cell 6 is where the old
    # handler was, and would run (and RETI) if the old timer still fired
    download(
        bench,
        [
            (P.GGP, 21, 2, 0),
            (P.CALC, 0, 0, 1),
            (P.AGP, 21, 2, 0),
            (P.WAIT, 0, 0, 10),
            (P.JA, 0, 0, 0),
            (P.STOP, 0, 0, 0),
            (P.SGP, 22, 2, 1),  # 6
            (P.RETI, 0, 0, 0),
        ],
    )
    it = bench.m.interp
    assert (it.vectors, it.enabled, it.global_enabled, it.timer_next) == ({}, set(), False, {})
    assert bench.value(P.APP_STATUS) == 0  # stopped, at 0
    assert bench.value(P.GGP, 0, 3) == 100  # bank 3 keeps the period
    bench.value(P.RUN_APP, 0, 0, 0)
    bench.advance(0.5)
    assert bench.value(P.GGP, 20, 2) == 3  # the old handler never ran again
    assert bench.value(P.GGP, 22, 2) == 0  # nor did its cell in the new code
    assert 4 <= bench.value(P.GGP, 21, 2) <= 6  # the new loop: every 100 ms


def test_stop_and_run_continue_with_the_programs_interrupts(bench: Bench) -> None:
    """Decision T29: 128 then 129 (no address) goes on where the program was, with what it
    set up; 131 resets it all, timers included."""
    download(bench, TIMER_PROGRAM)
    bench.value(P.RUN_APP, 1, 0, 0)
    bench.advance(0.25)
    bench.value(P.STOP_APP)
    bench.advance(1.0)
    assert bench.value(P.GGP, 20, 2) == 2
    bench.value(P.RUN_APP, 0, 0, 0)  # continue: the timer counts its period from here
    bench.advance(0.25)
    assert bench.value(P.GGP, 20, 2) == 4
    bench.value(P.STOP_APP)
    bench.value(P.RESET_APP)
    it = bench.m.interp
    assert (it.vectors, it.enabled, it.timer_next) == ({}, set(), {})
