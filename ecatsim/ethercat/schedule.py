"""What runs after a reply: the SYNC pulses, the ESCs' timers and the firmware behind the
PDI of each slave with a raised interrupt, then the EEPROM images to persist.

The silicon answers a frame at once and its firmware reacts later, over the PDI, to the
events the frame latched (decision P19). The segment's walk (ecatsim/ethercat/segment.py)
only latches; this schedule runs the reactions, at most every ``probe_ns`` of work looking
whether a frame waits, and stopping for it. SYNC0 pulses due before a frame's arrival fire
before its walk, each at its own time (decision DC2). On the daemon's link each slave's
firmware takes its outputs at the pulse, every slave's first, and the rest of its work (the
drive's cycle, the inputs as of the pulse) runs after, stopping for a waiting frame and
going on after its reply (decisions P30, P101).
Ref: TMC8460 §5.50.4 (SYNC0 generation), §5.42 (process-data watchdog); ETG.1000.6 §5.3
(DC synchronous mode), §6.4 (AL state machine run by the firmware).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence, Sized
from typing import Protocol

from ecatsim.esc.context import NO_DEADLINE, FrameContext
from ecatsim.esc.core import Esc
from ecatsim.slave.firmware import Firmware

#: overdue SYNC0 pulses fired one by one before the rest are skipped (a stall this long,
#: or a forward jump of the system time, is not caught up). Decision DC2.
MAX_SYNC0_CATCHUP = 64
#: frames arriving this long before the earliest SYNC deadline skip the per-slave check;
#: larger than any clock correction that does not mark the timers dirty (dc.MOVE_NS)
PULSE_HINT_MARGIN_NS = 200_000
#: the work after a reply looks whether a frame is waiting (``Schedule.frame_waiting``)
#: after its first slave and then once per this many ns of firmware work, and leaves the
#: rest for after that frame (decisions P19, P98)
PROBE_NS = 50_000


class Serviceable(Protocol):
    """What runs behind an ESC's PDI: the slave's firmware."""

    def service(self, now_ns: int) -> None: ...

    def reset(self) -> None: ...


class Schedule:
    """The work after the replies of one segment's ESCs (``escs`` in wire position order,
    ``firmware`` by the same position)."""

    #: fixed attributes (the compiled core declares them in schedule.pxd)
    __slots__ = (
        "_next_sync",
        "_pulse_hint",
        "_sync_escs",
        "awake",
        "ctx",
        "deferred",
        "escs",
        "firmware",
        "frame_waiting",
        "held_logs",
        "now_ns",
        "persist",
        "probe_ns",
        "resume_pos",
        "sync0_deferred",
        "sync0_late_ns",
        "sync0_merged",
        "sync0_ticks",
        "write_logs",
        "yielded",
    )

    def __init__(
        self,
        escs: Sequence[Esc],
        ctx: FrameContext,
        firmware: Sequence[Serviceable] = (),
        persist: Callable[[int], None] | None = None,
    ) -> None:
        self.escs = list(escs)
        self.ctx = ctx
        #: the firmware by position (the segment's list itself, not a copy)
        self.firmware = firmware if isinstance(firmware, list) else list(firmware)
        self.persist = persist
        #: True when a frame waits to be received (the daemon's link): the firmware's work
        #: after a reply stops for it and goes on after that frame's reply (decision P19);
        #: None: the work runs to its end
        self.frame_waiting: Callable[[], bool] | None = None
        #: the segment clock's time (the daemon's link): SYNC pulses that fall due while
        #: firmware works fire at their time, not when the next frame comes (P30); None:
        #: only at the start of the work and before a frame
        self.now_ns: Callable[[], int] | None = None
        #: log lines held while the daemon serves (ecatsim/logqueue.py), written by
        #: ``write_logs(frame_waiting)`` once the firmware's work is done (decision P37)
        self.held_logs: Sized = ()
        self.write_logs: Callable[[Callable[[], bool] | None], int] | None = None
        #: times the work after a reply stopped for a waiting frame
        self.yielded = 0
        #: the position the next round of firmware work starts at (0: the first)
        self.resume_pos = 0
        #: how often (ns of work) the work after a reply looks for a waiting frame
        self.probe_ns = PROBE_NS
        #: positions whose service runs after every frame, interrupt or not: the TMC8460
        #: MFCIO blocks, which watch the memory blocks and the frames continuously
        self.awake: frozenset[int] = frozenset()
        self._sync_escs: list[Esc] = []
        self.sync0_ticks = 0
        self.sync0_late_ns = 0
        #: firmware whose pulse's work was latched for after a waiting frame, in pulse
        #: order (one whose ``sync_ns`` is back to -1 has run it already; decision P30)
        self.deferred: list[Firmware] = []
        #: pulses latched with their work after (on the daemon's link, every one: P101);
        #: pulses that replaced one whose work still waited for a frame
        self.sync0_deferred = 0
        self.sync0_merged = 0
        #: host time before which no SYNC pulse can be due (recomputed by sync_until)
        self._pulse_hint = 0
        #: host time of the earliest SYNC0/SYNC1 pulse (NO_DEADLINE: none)
        self._next_sync = 0

    def service_at(self, t: int) -> None:
        """Fire the SYNC0 pulses due by host time ``t``, run the timers due, the firmware
        of every slave with a raised PDI interrupt (stopping for a waiting frame; the
        pulses that fall due meanwhile fire at their time and their work runs before the
        next slave's: P30, P101), then persist the EEPROM images that changed. Never called
        between receive and reply."""
        ctx = self.ctx
        if t >= self._pulse_hint or ctx.timers_dirty:
            self.sync_until(t, False)  # first: each pulse is handled at its own time
        if t >= ctx.wd_next:  # a watchdog may be due: each one looked at (decision P100)
            for esc in self.escs:
                d = esc.wd.deadline_ns
                if d and t >= d:  # due (the running watchdogs of a cyclic bus are not)
                    esc.check_timers(t)
            self._wd_scan()
        if self.deferred and not self.run_deferred():
            return  # a frame waits: the rest after its reply (decision P30)
        if (ctx.n_raised or self.awake) and self.firmware:
            probe = self.frame_waiting
            # the first look after the first slave: frames that came while the work before ran
            # (a master's burst of frames, the frames of one cycle) wait for one slave's work,
            # not for PROBE_NS of it (decision P98)
            look = time.monotonic_ns() if probe is not None else NO_DEADLINE
            order = sorted(ctx.pending | self.awake)
            first = self.resume_pos
            if first:  # where the last round stopped: every slave gets its turn (P19)
                order = [p for p in order if p >= first] + [p for p in order if p < first]
            for pos in order:
                ctx.pdi_ns = t
                self.firmware[pos].service(t)
                if look != NO_DEADLINE and time.monotonic_ns() >= look:
                    if probe is not None and probe():
                        # the silicon answers while its firmware works: the frame first,
                        # the slaves not served yet keep their raised interrupt (P19)
                        self.yielded += 1
                        self.resume_pos = pos + 1
                        return
                    # their work before the other slaves' (a slave's SYNC0 interrupt comes
                    # before its main loop): not merged into the next pulse's (P30)
                    if not self.pulses_and_their_work():
                        self.resume_pos = pos + 1
                        return  # a frame waits (run_deferred's look)
                    look = time.monotonic_ns() + self.probe_ns
            self.resume_pos = 0
            if self.deferred and not self.run_deferred():
                return  # pulses latched meanwhile (P101); a frame waits: after its reply
        if ctx.flush and self.persist is not None:
            for pos in sorted(ctx.flush):
                self.persist(pos)
            ctx.flush.clear()
        if self.held_logs and self.write_logs is not None:
            self.write_held_logs()  # the lines held meanwhile (decision P37)

    def write_held_logs(self) -> None:
        """Write the log lines held while frames were served (decision P37), stopping for
        a frame that waits. A SYNC pulse that falls due meanwhile stops them too: it fires
        at its own time and its work runs first (P101), then the lines go on. Nothing
        while ``write_logs`` is not set (the daemon sets it while it serves)."""
        write = self.write_logs
        if write is None:
            return
        probe = self.frame_waiting
        idle = 0  # rounds in a row that wrote no line (a pulse that never fires: stop)
        while self.held_logs and idle < 2:
            idle = idle + 1 if write(self._logs_stop) == 0 else 0
            if not self.held_logs or (probe is not None and probe()):
                return
            if not self.pulses_and_their_work():
                return  # a frame waits: the rest after its reply

    def pulses_and_their_work(self) -> bool:
        """The SYNC pulses that fell due meanwhile (``pulses_meanwhile``), then the work
        latched for them (``run_deferred``, P101). False if it stopped for a waiting frame."""
        self.pulses_meanwhile()
        return not self.deferred or self.run_deferred()

    def _logs_stop(self) -> bool:
        """Asked before each held log line: a frame waits, or a SYNC pulse is due (only
        where the segment's time is known: ``now_ns``, the daemon's link)."""
        probe = self.frame_waiting
        if probe is not None and probe():
            return True
        clock = self.now_ns
        return clock is not None and (clock() >= self._next_sync or self.ctx.timers_dirty)

    def pulses_due(self, t: int) -> None:
        """The pulses due before a frame that arrived at ``t``: sync_until(t, True), unless
        no pulse can be due by ``t`` (the per-frame fast path)."""
        if t >= self._pulse_hint or self.ctx.timers_dirty:
            self.sync_until(t, True)

    def sync_until(self, t: int, frame_first: bool = False) -> None:
        """Fire every SYNC0 pulse due by ``t`` in time order, each handled by the firmware
        at the pulse's own time: outputs received before the pulse are applied and inputs
        captured as of that instant, however late the host gets to it. Called before a
        frame that arrived at ``t`` is processed (``frame_first``), and from the timers.

        On the daemon's link (``frame_waiting`` set) each pulse only latches its outputs
        here (``Firmware.sync0_latch``), every slave's first, and the work runs after, from
        ``service_at`` (``run_deferred``, which stops for a waiting frame): a frame that
        comes meanwhile waits for the latches, not for the drives' work (decision P101).
        A further pulse of the same slave due by ``t`` (the host was late: DC2) runs the
        last one's work and its own at once, looking whether a frame waits after the first
        such slave and then every ``probe_ns``; once one waits (always before a frame,
        ``frame_first``), it replaces the latched one instead (P30, P98).
        Ref: TMC8460 §5.50.4 (SYNC0 generation); ETG.1000.6 §5.3 (DC synchronous mode).
        """
        ctx = self.ctx
        nxt = NO_DEADLINE
        probe = self.frame_waiting
        link = probe is not None
        # a frame waits: a further pulse replaces the latched one (P30)
        defer = frame_first and link
        # the first look after the first slave's work (P98)
        look = time.monotonic_ns() if link else NO_DEADLINE
        for esc in self.sync_escs:
            dc = esc.dc
            fw = self.firmware[esc.position] if self.firmware else None
            # the TMC8670's firmware is called in C (any other through Python; P32)
            cfw = fw if isinstance(fw, Firmware) else None
            for k in range(MAX_SYNC0_CATCHUP + 1):
                # NO_DEADLINE: no pulse scheduled (later than any host time t)
                d1 = dc.sync1_deadline_or(NO_DEADLINE)
                d = dc.sync0_deadline_or(NO_DEADLINE)
                if d1 <= t and d1 < d:
                    esc.sync1_tick()  # registers only: the firmware acts on SYNC0
                    continue
                if d > t:
                    break
                if k == MAX_SYNC0_CATCHUP:
                    d = t  # too far behind: fire once now, the missed pulses are skipped
                esc.sync0_tick(d)
                self.sync0_ticks += 1
                if t - d > self.sync0_late_ns:
                    self.sync0_late_ns = t - d
                if fw is not None and esc.irq_line:  # in ctx.pending (a C field)
                    ctx.pdi_ns = d
                    if cfw is None:
                        fw.service(d)
                        continue
                    ran = True  # a slave's work ran: a look follows if one is due (P98)
                    if defer or (link and k == 0):  # latched, the work after (P101)
                        waiting = cfw.sync_ns >= 0
                        ran = waiting and not defer
                        if ran:
                            # no frame waits: the last pulse's work first, at its time (it
                            # stays in ``deferred``, where the new pulse's work will run)
                            ctx.pdi_ns = cfw.sync_ns
                            cfw.run_latched()
                            ctx.pdi_ns = d
                        if cfw.sync0_latch(d):
                            self.sync0_deferred += 1
                            if not waiting:
                                self.deferred.append(cfw)
                            elif not ran:
                                self.sync0_merged += 1  # the slave's cycle overran
                    else:
                        cfw.service(d)  # a further pulse: the last one's work first (DC2)
                    # off the link ``look`` is NO_DEADLINE, never reached
                    if ran and time.monotonic_ns() >= look:
                        if probe is not None and probe():
                            defer = True  # the frame first (decision P30)
                        else:
                            look = time.monotonic_ns() + self.probe_ns
            else:
                d = dc.sync0_deadline_or(NO_DEADLINE)
                d1 = dc.sync1_deadline_or(NO_DEADLINE)
            nxt = min(nxt, d, d1)
        self._set_next_sync(nxt)

    def run_deferred(self) -> bool:
        """Run the pulses' work latched for after a frame (``deferred``, in pulse order),
        each at its pulse's time, looking after the first slave's work and then every
        ``probe_ns`` whether a frame waits and whether SYNC pulses fell due meanwhile
        (they fire then, at their own time, not when the next frame comes). False if it
        stopped for a frame (the rest stays latched). Decisions P30, P98."""
        lst = self.deferred
        probe = self.frame_waiting
        # the first look after the first slave's work (P98)
        look = time.monotonic_ns() if probe is not None else NO_DEADLINE
        ctx = self.ctx
        i = 0
        while i < len(lst):  # pulses that fall due meanwhile may add to it
            fw = lst[i]
            i += 1
            if fw.sync_ns < 0:
                continue  # run already, before a later pulse or event of its slave
            ctx.pdi_ns = fw.sync_ns
            fw.run_latched()
            if look != NO_DEADLINE:
                now = time.monotonic_ns()
                if now >= look:
                    if probe is not None and probe():
                        self.yielded += 1
                        del lst[:i]
                        return False
                    self.pulses_meanwhile()
                    look = time.monotonic_ns() + self.probe_ns
        lst.clear()
        return True

    def pulses_meanwhile(self) -> None:
        """The SYNC pulses that fell due while the firmware worked, fired now, each at its
        own time (``now_ns`` set: the daemon's link; decision P30)."""
        clock = self.now_ns
        if clock is not None:
            now = clock()
            # the earliest deadline itself, not the frames' hint before it: a look in the
            # hint's margin would scan every ESC for nothing (a pulse a clock correction
            # moved earlier still fires at its own time, only found a little later)
            if now >= self._next_sync or self.ctx.timers_dirty:
                self.sync_until(now, False)

    def _set_next_sync(self, nxt: int) -> None:
        self._next_sync = nxt
        self._pulse_hint = nxt - PULSE_HINT_MARGIN_NS

    def _refresh_next_sync(self) -> None:
        """Recompute the earliest SYNC deadline (after a DC register change)."""
        nxt = NO_DEADLINE
        for esc in self.sync_escs:
            for d in (esc.dc.sync0_deadline(), esc.dc.sync1_deadline()):
                if d is not None and d < nxt:
                    nxt = d
        self._set_next_sync(nxt)

    @property
    def sync_escs(self) -> list[Esc]:
        """ESCs whose SYNC unit runs (recomputed when an activation changes)."""
        if self.ctx.timers_dirty:
            self.ctx.timers_dirty = False
            self._sync_escs = [e for e in self.escs if e.dc.sync0_on]
        return self._sync_escs

    def next_deadline(self) -> int | None:
        """The earliest timer deadline (ns), for the daemon's poll timeout, None if there
        is none. SYNC deadlines are those computed when the pulses last ran or a DC
        register last changed; the time loop moves them by less than the ESC's MOVE_NS
        until it marks them stale. The watchdogs are looked at only where their bound
        (``FrameContext.wd_next``) comes before the SYNC pulses: on a cyclic bus the
        triggers keep their deadlines far off (decision P100)."""
        best = self.next_deadline_ns()
        if self.ctx.wd_next == best:  # the bound may be early: the watchdogs' own
            best = min(self._wd_scan(), self._next_sync)
        return None if best == NO_DEADLINE else best

    def next_deadline_ns(self) -> int:
        """When to look at the timers again, ``NO_DEADLINE`` if never (the compiled
        responder's call after each frame: a C integer): the earliest SYNC pulse, or the
        watchdogs' bound where it comes first. The bound is never late and may be early (a
        watchdog triggered again since); waking at it, ``service_at`` looks at every
        watchdog and makes it exact, so a segment without SYNC pulses looks at them once
        per expiry or bound, not after every frame (decision P102)."""
        if self.ctx.timers_dirty:
            self._refresh_next_sync()
        best = self._next_sync
        w = self.ctx.wd_next
        return w if w < best else best

    def _wd_scan(self) -> int:
        """The earliest deadline of a running process-data watchdog (``NO_DEADLINE``:
        none runs), kept as the segment's bound ``FrameContext.wd_next`` (P100)."""
        w = NO_DEADLINE
        for e in self.escs:
            d = e.wd.deadline_ns
            if d and d < w:
                w = d
        self.ctx.wd_next = w
        return w
