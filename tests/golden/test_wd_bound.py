"""The segment's bound on its process-data watchdogs (decisions P100, P102): the schedule
looks at each watchdog only once the earliest deadline any trigger set can be due, and
still expires every one at its own deadline, as the per-frame look at every ESC did; the
timers' next look is that bound, never later than a deadline.
Ref: TMC8460 §5.39-5.43 Tables 53-57."""

from __future__ import annotations

import random
import struct

from ecatsim.esc.context import NO_DEADLINE
from tests.support.tinymaster import TinyMaster, segment_of

N = 4
INC_NS = 100_000  # the default divider 0x09C2: (2498 + 2) x 40 ns


def _to_safeop(m: TinyMaster, pos: int) -> None:
    m.apwr(pos, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(pos, 0x0808, struct.pack("<HHBBBB", 0x1080, 128, 0x22, 0, 1, 0))
    m.apwr(pos, 0x0120, b"\x02\x00")
    # SM2 with the watchdog trigger (control bit 6), SM3 the inputs
    m.apwr(pos, 0x0810, struct.pack("<HHBBBB", 0x1100, 12, 0x64, 0, 1, 0))
    m.apwr(pos, 0x0818, struct.pack("<HHBBBB", 0x1200, 17, 0x20, 0, 1, 0))
    m.apwr(pos, 0x0120, b"\x04\x00")
    assert m.aprd(pos, 0x0130, 1).data == b"\x04"


def test_every_watchdog_expires_at_its_deadline_and_the_next_deadline_is_exact() -> None:
    """Random triggers, time settings (0: off), resets and waits on four slaves, against a
    model of each watchdog: after every step the expiry counters (0x0442), the status bit
    (0x0440.0) and ``next_deadline()`` are exactly the model's."""
    rng = random.Random(100)
    seg, clock = segment_of(N)
    m = TinyMaster(seg, clock)
    for pos in range(N):
        _to_safeop(m, pos)
    timeout = [1000 * INC_NS] * N  # 0x0420 default 1000 increments: 100 ms
    deadline = [0] * N
    expired = [0] * N
    # 0x0440.0: 1 active or disabled, 0 expired (§5.42 Table 56); as the bring-up left it
    status = [m.aprd(pos, 0x0440, 1).data[0] & 1 for pos in range(N)]
    for pos in range(N):  # the counters as the bring-up left them (none expired yet)
        assert m.aprd(pos, 0x0442, 1).data == b"\x00"
    for step in range(400):
        act = rng.random()
        pos = rng.randrange(N)
        if act < 0.45:  # outputs: a trigger at the frame's time
            m.apwr(pos, 0x1100, bytes(12))
            status[pos] = 1
            if timeout[pos]:
                deadline[pos] = clock.now_ns() + timeout[pos]
        elif act < 0.55:  # another watchdog time, 0 stops it
            t = rng.choice([0, 1, 3, 20, 1000])
            m.apwr(pos, 0x0420, struct.pack("<H", t))
            timeout[pos] = t * INC_NS
            if t == 0:
                deadline[pos] = 0
                status[pos] = 1
        elif act < 0.58:  # a power cycle of one ESC: its watchdog stops
            seg.escs[pos].hardware_reset()
            timeout[pos] = 1000 * INC_NS
            deadline[pos] = 0
            expired[pos] = 0
            status[pos] = m.aprd(pos, 0x0440, 1).data[0] & 1
            _to_safeop(m, pos)
        else:  # time passes; the timers run, each watchdog due expires
            clock.advance(rng.choice([10_000, 90_000, 150_000, 400_000, 2_000_000, 50_000_000]))
            seg.service()
            now = clock.now_ns()
            for k in range(N):
                if deadline[k] and now >= deadline[k]:
                    deadline[k] = 0
                    expired[k] += 1
                    status[k] = 0
        running = [d for d in deadline if d]
        assert seg.schedule.next_deadline_ns() <= min(running, default=NO_DEADLINE), step
        assert seg.schedule.next_deadline() == (min(running) if running else None), step
        for k in range(N):
            assert m.aprd(k, 0x0442, 1).data == bytes([min(expired[k], 0xFF)]), (step, k)
            assert m.aprd(k, 0x0440, 1).data[0] & 1 == status[k], (step, k)
    assert sum(expired) > 10  # the walk did expire watchdogs, not only restart them


def test_the_timers_look_at_the_bound_then_at_the_exact_deadline() -> None:
    """On a segment without SYNC pulses (P102) a watchdog triggered again leaves the timers'
    next look at the first deadline, early; looking then expires nothing and makes the next
    look exact, and the watchdog expires at its own deadline."""
    seg, clock = segment_of(1)
    m = TinyMaster(seg, clock)
    _to_safeop(m, 0)
    s = seg.schedule
    m.apwr(0, 0x1100, bytes(12))
    first = clock.now_ns() + 1000 * INC_NS
    clock.advance(40_000_000)
    m.apwr(0, 0x1100, bytes(12))  # triggered again: the deadline moves out
    second = clock.now_ns() + 1000 * INC_NS
    assert s.next_deadline_ns() == first  # the bound, no watchdog looked at
    clock.advance(first - clock.now_ns())
    seg.service()  # the timers' look at the bound
    assert m.aprd(0, 0x0442, 1).data == b"\x00"  # nothing expired
    assert s.next_deadline_ns() == second == s.next_deadline()
    clock.advance(second - clock.now_ns())
    seg.service()
    assert m.aprd(0, 0x0442, 1).data == b"\x01"
    assert m.aprd(0, 0x0440, 1).data[0] & 1 == 0  # expired
    assert s.next_deadline_ns() == NO_DEADLINE
    assert s.next_deadline() is None
