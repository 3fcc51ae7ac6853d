"""The SYNC0 work on the daemon's link (decisions P30, P101): each slave's firmware takes
its outputs at the pulse, every slave's first, and the rest of its work runs after; where a
frame waits, after that frame's reply. The frame reads the inputs the slave last wrote; the
work, once run, gives exactly the inputs an undelayed run gives (the same outputs, the same
pulse time)."""

from __future__ import annotations

from collections.abc import Callable

from ecatsim.logqueue import LogQueue
from tests.perf.hotpath import IN, MS, OUT, CspCycle
from tests.support.tinymaster import drive_of, firmware_of, firmwares

N = 4
#: how long an OP request waits for outputs (decision F5; a C constant of the compiled
#: firmware, not visible from Python)
OP_WAIT_NS = 9_000_000_000
#: where the LRW's data starts in the frame: Ethernet 14, EtherCAT 2, datagram header 10
DATA = 26


def inputs(reply: bytes, i: int) -> bytes:
    """Drive ``i``'s inputs in a cyclic frame's reply."""
    at = DATA + OUT * N + IN * i
    return reply[at : at + IN]


def without_inputs(reply: bytes) -> bytes:
    at = DATA + OUT * N
    return reply[:at] + reply[at + IN * N :]


def latched(c: CspCycle) -> list[bool]:
    return [fw.sync_ns >= 0 for fw in firmwares(c.seg)]


def twins() -> tuple[CspCycle, CspCycle, list[bool], list[bytes]]:
    """Two equal segments of N enabled drives in csp after one more cycle, and the drives'
    inputs in its reply; the second's link says whether a frame waits (``waiting[0]``),
    looked at after every slave's work."""
    ref, c = CspCycle(N), CspCycle(N)
    first = ref.step()
    assert c.step() == first
    waiting = [False]
    c.seg.schedule.frame_waiting = lambda: waiting[0]
    c.seg.schedule.probe_ns = 0
    return ref, c, waiting, [inputs(first, i) for i in range(N)]


def test_a_frame_that_waits_reads_the_inputs_written_before_and_the_work_goes_on_after_it() -> None:
    ref, c, waiting, last = twins()
    moved = 0
    for k in range(40):
        ref.pulse()
        waiting[0] = True  # a frame arrives while the pulses' work runs
        c.pulse()
        # every pulse latched first (P101); slave 0's work ran before the look, which
        # found the frame
        assert latched(c) == [False, True, True, True]
        assert c.seg.schedule.sync0_deferred == N * (k + 1)
        waiting[0] = False
        want, got = ref.exchange(), c.exchange()
        assert without_inputs(got) == without_inputs(want)  # WKCs, system time, outputs
        assert inputs(got, 0) == inputs(want, 0)
        for i in (1, 2, 3):  # the inputs of the last pulse their firmware finished
            assert inputs(got, i) == last[i]
        assert latched(c) == [False] * N  # run after the reply, with the pulse's outputs
        assert c.seg.schedule.deferred == []
        moved += inputs(want, 3) != last[3]
        last = [inputs(want, i) for i in range(N)]
    assert moved > 30  # the drives move: a stale input or a wrong output would show
    assert c.seg.schedule.sync0_merged == 0
    assert c.seg.schedule.yielded == 40


def test_the_pulses_due_before_a_frame_only_latch_before_it() -> None:
    ref, c, _, last = twins()  # no frame waits behind it: the work after it runs to its end
    for _ in range(20):
        # no timer ran: the pulse is due when the frame arrives and comes before its walk,
        # which waits for the latches only (P101)
        want, got = ref.exchange(), c.exchange()
        assert without_inputs(got) == without_inputs(want)
        for i in range(N):
            assert inputs(got, i) == last[i]  # their work ran after the reply
        assert latched(c) == [False] * N
        last = [inputs(want, i) for i in range(N)]
    assert c.seg.schedule.sync0_deferred == N * 20


def test_a_pulse_that_comes_while_the_last_ones_work_waits_replaces_it() -> None:
    _, c, waiting, _ = twins()
    waiting[0] = True
    c.clock.t = c.t + MS + 20_000  # two pulses due: the host got to them late
    c.daemon._service_timers()
    s = c.seg.schedule
    # every slave's first pulse latched (P101); slave 0's second ran the first's work
    # and its own, then the look found the frame: slaves 1-3's second pulse latched and
    # replaced the first (their cycle overran), no work run for it
    assert s.sync0_deferred == N + 3
    assert s.sync0_merged == 3
    # then slave 1's latched work ran before the next look, which found the frame
    assert latched(c) == [False, False, True, True]
    assert all(c.t + MS <= fw.sync_ns < c.t + MS + 20_000 for fw in firmwares(c.seg)[2:])
    waiting[0] = False
    c.seg.service_at(c.clock.t)
    assert latched(c) == [False] * N
    assert [drive_of(c.seg, k).state.name for k in range(N)] == ["OPERATION_ENABLED"] * N


def test_without_the_daemons_link_the_work_is_never_deferred() -> None:
    c = CspCycle(N)  # in process: no frame_waiting, the pulses' work runs at once
    assert c.seg.schedule.frame_waiting is None
    c.pulse()
    c.exchange()
    c.clock.t = c.t + 3 * MS
    c.exchange()
    assert c.seg.schedule.sync0_deferred == 0
    assert latched(c) == [False] * N


def test_pulses_that_fall_due_while_the_latched_work_runs_fire_at_their_time() -> None:
    _, c, waiting, _ = twins()
    s = c.seg.schedule
    waiting[0] = True
    c.pulse()
    assert latched(c) == [False, True, True, True]
    waiting[0] = False
    ticks = s.sync0_ticks
    c.clock.t = c.t + MS + 20_000  # the next pulse falls due while the work runs
    assert s.run_deferred()
    assert s.sync0_ticks == ticks  # the segment's time is not known: no pulse fires
    c.t += MS
    waiting[0] = True
    c.pulse()  # the timer: that pulse, and a frame waits again
    waiting[0] = False
    ticks = s.sync0_ticks
    assert latched(c) == [False, True, True, True]
    c.seg.schedule.now_ns = lambda: c.clock.t
    c.clock.t = c.t + MS + 20_000
    assert s.run_deferred()
    # slave 1's latched work ran, then the look found the pulse due: every slave's, at
    # its time (slaves 2 and 3's latched work first, P101), none replaced
    assert s.sync0_ticks == ticks + N
    assert latched(c) == [False] * N
    assert s.deferred == []
    assert s.sync0_merged == 0


def test_a_pulse_on_latched_work_runs_it_first_and_looks_for_a_frame() -> None:
    """A pulse that finds a slave's last work still latched runs that work first when no
    frame waits, then looks, as after any slave's work (P98, P101): once a frame waits,
    the other slaves' new pulses replace their latched ones (P30)."""
    _, c, waiting, _ = twins()
    s = c.seg.schedule
    waiting[0] = True
    c.pulse()
    assert latched(c) == [False, True, True, True]
    assert (s.sync0_deferred, s.sync0_merged) == (N, 0)
    c.t += MS
    c.pulse()  # the frame still waits
    # slave 0: latched anew; slave 1: its last work, then the new latch, then the look
    # found the frame; slaves 2, 3: replaced; then slave 1's new work before the look
    assert (s.sync0_deferred, s.sync0_merged) == (2 * N, 2)
    assert latched(c) == [True, False, True, True]
    assert all(c.t <= fw.sync_ns < c.t + 20_000 for fw in firmwares(c.seg)[2:])
    waiting[0] = False
    assert s.run_deferred()
    assert latched(c) == [False] * N
    assert [drive_of(c.seg, k).state.name for k in range(N)] == ["OPERATION_ENABLED"] * N


def test_an_emcy_the_latched_work_queues_behind_a_full_sm1_unmasks_the_sm1_event() -> None:
    """A following error in a drive's latched cycle while SM1 still holds an earlier
    reply: its EMCY waits in the queue, and the firmware wants the SM1 event (the master's
    read of SM1) to send it then, as after a cycle run at once."""
    _, c, waiting, _ = twins()
    fw = firmware_of(c.seg, 3)
    esc = c.seg.escs[3]
    assert fw.emergency is not None and fw.od is not None and fw.mbx is not None
    fw.emergency.clear()  # EMCY 0000h: SM1 full until the master reads it
    sm1_status, al_event_mask, ev_sm1 = 0x0805 + 8, 0x0204, 0x0200
    assert esc.mem[sm1_status] & 0x08
    assert not int.from_bytes(esc.mem[al_event_mask : al_event_mask + 4], "little") & ev_sm1
    fw.od.set(0x6065, 0, 1)  # following error window: 1 count
    c.t += 20 * MS  # the cosine target is well under way 20 ms on: the error is larger
    c.clock.t = c.t + 20_000
    waiting[0] = True
    c.daemon._service_timers()
    assert latched(c)[3]
    waiting[0] = False
    assert c.seg.schedule.run_deferred()
    assert drive_of(c.seg, 3).state.name == "FAULT"
    assert fw.mbx.held is not None  # the following error's EMCY, behind the first
    assert int.from_bytes(esc.mem[al_event_mask : al_event_mask + 4], "little") & ev_sm1


def slow_looks() -> tuple[CspCycle, CspCycle, list[bool], list[int]]:
    """twins() with looks due every 10 s, each look counted (``asked[0]``)."""
    ref, c, waiting, _ = twins()
    asked = [0]

    def frame_waits() -> bool:
        asked[0] += 1
        return waiting[0]

    c.seg.schedule.frame_waiting = frame_waits
    c.seg.schedule.probe_ns = 10_000_000_000
    return ref, c, waiting, asked


def test_before_a_frame_the_pulses_latch_without_a_look() -> None:
    """The pulses due before a frame only latch, whatever the probe time (10 s here): the
    frame is known to wait, so no look is asked for (decision P101). After the reply the
    latched work looks after its first slave (P98), finds no other frame and runs to its
    end, the looks reading the host's monotonic clock (P67)."""
    ref, c, _, asked = slow_looks()
    s = c.seg.schedule
    first = ref.exchange()
    c.exchange()
    last = [inputs(first, i) for i in range(N)]
    for k in range(1, 6):
        want, got = ref.exchange(), c.exchange()  # no timer ran: the pulse came first
        assert without_inputs(got) == without_inputs(want)
        for i in range(N):
            assert inputs(got, i) == last[i]  # latched, their work after the reply
        assert latched(c) == [False] * N
        assert (s.sync0_deferred, asked[0]) == (N * (k + 1), k + 1)
        last = [inputs(want, i) for i in range(N)]
    assert s.sync0_merged == 0


def test_from_the_timers_the_first_look_comes_after_the_first_slave() -> None:
    """A pulse served by the timers looks whether a frame waits after its first slave's work,
    whatever the probe time: the frames of a cycle sent just after SYNC0 wait for one
    slave's work, not for probe_ns of it (decision P98); after that look, every probe_ns."""
    ref, c, waiting, asked = slow_looks()
    s = c.seg.schedule
    for k in range(5):
        ref.pulse()
        c.pulse()
        assert asked[0] == k + 1  # one look, after the first slave; none due after it
        assert latched(c) == [False] * N
        assert ref.exchange() == c.exchange()
    assert s.sync0_deferred == 5 * N  # every pulse latched first (P101)
    waiting[0] = True
    c.pulse()
    assert latched(c) == [False, True, True, True]  # as in the first test, probe_ns 0
    assert s.sync0_deferred == 6 * N


def same_escs(a: CspCycle, b: CspCycle) -> None:
    """Every ESC's whole memory alike: registers (AL status and code, the event mask the
    firmware sets, SM and DC state) and process data."""
    for x, y in zip(a.seg.escs, b.seg.escs, strict=True):
        assert x.mem == y.mem


def test_on_the_link_from_power_up_every_slave_is_as_in_process() -> None:
    """Every pulse latched first and its work run after (P101), from the first pulse on
    (after which the firmware masks the process-data events), through the drives'
    enabling and 30 cycles: ESC memories after each pulse and replies as in process,
    where each pulse's work runs at once."""
    ref = CspCycle(N, enable=False)
    c = CspCycle(N, enable=False, frame_waiting=lambda: False)
    for cw in (0x06, 0x07, 0x0F, 0x0F) + (0x0F,) * 30:
        ref.pulse()
        c.pulse()
        same_escs(ref, c)
        assert ref.exchange(cw) == c.exchange(cw)
    assert ref.seg.schedule.sync0_deferred == 0
    assert c.seg.schedule.sync0_deferred == c.seg.schedule.sync0_ticks == N * 34
    assert all(fw.pd_masked for fw in firmwares(c.seg))
    assert [drive_of(c.seg, k).state.name for k in range(N)] == ["OPERATION_ENABLED"] * N


def test_an_op_request_that_waited_too_long_fails_in_the_latched_work_too() -> None:
    """The OP request that waits for outputs fails with 0x001B after OP_WAIT_NS (decision
    F5) when the pulse's work was latched, as when it runs at once."""
    ref = CspCycle(N)
    c = CspCycle(N, frame_waiting=lambda: False)
    for cyc in (ref, c):
        firmware_of(cyc.seg, 2).op_requested_ns = cyc.t - OP_WAIT_NS
        cyc.pulse()
        mem = cyc.seg.escs[2].mem
        assert (mem[0x0130], bytes(mem[0x0134:0x0136])) == (0x14, b"\x1b\x00")  # SAFEOP + error
    same_escs(ref, c)


def test_pulses_that_fall_due_while_held_log_lines_are_written_fire_at_their_time() -> None:
    """The log lines held while frames were served are written after the work (P37). A
    SYNC pulse that falls due while they are written fires at its time, and its work
    runs, before the next line: slow lines never hold the slaves' cycle back."""
    _, c, _, _ = twins()
    s = c.seg.schedule
    s.now_ns = lambda: c.clock.t
    queue = LogQueue()
    ticks = s.sync0_ticks
    written: list[tuple[str, int]] = []

    def render(logger: object, event: str, **kw: object) -> None:
        written.append((event, (s.sync0_ticks - ticks) // N))
        c.clock.t += 350_000  # one line: 0.35 ms of the host's time

    queue.write["info"] = render
    queue.held.extend((None, "info", f"line {i}", {}) for i in range(10))
    s.held_logs, s.write_logs = queue.held, queue.drain
    c.clock.t = c.t - 500_000  # mid-cycle: the next pulses at c.t, c.t + 1 ms, + 2 ms
    assert s.sync0_late_ns < 100_000
    s.service_at(c.clock.t)
    # the clock after line k is c.t - 0.5 ms + (k + 1) x 0.35 ms: each pulse fired
    # before the first line that started after it, 0.2, 0.25 and 0.3 ms late
    assert written == [(f"line {k}", p) for k, p in enumerate((0, 0, 1, 1, 1, 2, 2, 2, 3, 3))]
    assert s.sync0_ticks == ticks + 3 * N
    assert abs(s.sync0_late_ns - 300_000) < 10_000
    assert latched(c) == [False] * N  # every pulse's work ran
    assert len(queue.held) == 0 and s.sync0_merged == 0


def test_a_frame_that_waits_stops_the_held_log_lines() -> None:
    _, c, waiting, _ = twins()
    s = c.seg.schedule
    s.now_ns = lambda: c.clock.t
    queue = LogQueue()
    written: list[str] = []

    def render(logger: object, event: str, **kw: object) -> None:
        written.append(event)
        waiting[0] = event == "line 0"  # a frame comes while the first line is written

    queue.write["info"] = render
    queue.held.extend((None, "info", f"line {i}", {}) for i in range(3))
    s.held_logs, s.write_logs = queue.held, queue.drain
    c.clock.t = c.t - 500_000
    s.service_at(c.clock.t)
    assert written == ["line 0"]  # then the frame first
    waiting[0] = False
    s.service_at(c.clock.t)
    assert written == ["line 0", "line 1", "line 2"] and len(queue.held) == 0


class SlowRound:
    """Another slave's firmware work that takes ``ns`` of the host's time (an AL
    transition, a PDO map's compilation); ``then`` runs at its end."""

    def __init__(self, c: CspCycle, ns: int, then: Callable[[], None] | None = None) -> None:
        self.c, self.ns, self.then = c, ns, then

    def service(self, t: int) -> None:
        self.c.clock.t += self.ns
        if self.then is not None:
            self.then()


def test_pulses_that_fall_due_in_a_long_firmware_round_run_before_the_next_slave() -> None:
    """A long round of other slaves' firmware (512 AL transitions take about 10 ms): a
    pulse that falls due meanwhile fires at its time and its work runs before the next
    slave's, as a slave's SYNC0 interrupt comes before its main loop. A frame that comes
    later finds that work done, and its own pulse replaces nothing (P30)."""
    _, c, waiting, _ = twins()
    s = c.seg.schedule
    s.now_ns = lambda: c.clock.t

    def frame_comes() -> None:
        waiting[0] = True

    s.firmware = [*s.firmware, SlowRound(c, 1_200_000), SlowRound(c, 1_200_000, frame_comes)]
    s.awake = frozenset({N, N + 1})
    c.clock.t = c.t - 500_000  # the next pulses at c.t and c.t + 1 ms
    ticks = s.sync0_ticks
    s.service_at(c.clock.t)
    # the first round: the pulse at c.t fell due in it, fired at the look after it and
    # its work ran; the second: the pulse at c.t + 1 ms fell due and a frame came, first
    assert s.sync0_ticks == ticks + N
    assert [firmware_of(c.seg, k).sync_ns >= 0 for k in range(N)] == [False] * N
    s.awake = frozenset()
    waiting[0] = False
    assert c.deliver(c.frames(c.cw)[0]) is not None
    assert s.sync0_ticks == ticks + 2 * N  # the second pulse, before the frame
    assert s.sync0_merged == 0  # each pulse's work ran: none replaced
    assert [firmware_of(c.seg, k).sync_ns >= 0 for k in range(N)] == [False] * N
