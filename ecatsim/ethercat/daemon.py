"""The one loop: receive a frame, process it in place, reply, then let the slaves react.

Blocking wake-up by default (select(2) on the link's fd with the next timer as timeout,
decision P1); ``busy_poll`` spins on a non-blocking receive instead. On a raw link the
compiled responder (ecatsim/ethercat/responder.pyx, decision P9) runs the steady state: it waits,
receives and answers each frame through the same segment calls as
:meth:`Daemon.handle_frame`, the reference, runs the work after each reply and the
segment's timers, and returns here only for what Python serves (the control socket, the
front doors, faults, delayed replies); it hands a frame to :meth:`handle_frame` where
something watches or alters frames (trace, faults).
With an out link (``--out-iface``: port 1 of the last slave leaves the process, decision
L9) the compiled responder, or the select(2) loop, serves both links (:class:`OutPort`).
A failure while processing a frame is counted and logged once with the last frames; the
loop carries on.
Ref: docs/architecture.md "Frame path".
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
from collections.abc import Callable
from types import FrameType
from typing import TYPE_CHECKING, Protocol

import structlog

from ecatsim.clock import MonotonicClock
from ecatsim.compiled import load
from ecatsim.doors.host import DoorHost
from ecatsim.ethercat.recorder import FrameRecorder
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.sequence import NOT_ECAT, REPLY, FrameSequence
from ecatsim.faults.engine import FaultEngine
from ecatsim.link.base import Link
from ecatsim.link.follow import CpuFollower
from ecatsim.logqueue import LogQueue
from ecatsim.wire.frame import ecat_offset

if TYPE_CHECKING:
    from ecatsim.ethercat.responder import Responder as ResponderType

responder = load("ecatsim.ethercat.responder")  # decision P9; None: the select(2) loop serves

log = structlog.get_logger("ecatsim.ethercat.daemon")

MAX_FRAME = 2048
#: the longest the loop sleeps with no timer due
IDLE_TIMEOUT_NS = 200_000_000
#: prctl(2) option: the slack the kernel may add to this thread's timer expiries
PR_SET_TIMERSLACK = 29
#: how often the out link's carrier is looked at (a cable plugged or pulled)
CARRIER_POLL_NS = 50_000_000


def fine_timer_slack() -> None:
    """Ask for 1 ns of timer slack: a normal thread's sleeps may otherwise end up to 50 us
    late, which is SYNC0 jitter (real-time threads get none anyway). Ref: prctl(2)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(1), 0, 0, 0)
    except (OSError, AttributeError):
        pass  # not Linux: the default slack stays


class ControlServer(Protocol):
    """The control socket as the loop sees it."""

    def fileno(self) -> int: ...

    def serve(self) -> None: ...


class OutPort:
    """The second link (``--out-iface``): frames leaving the segment's out port go out on
    it, frames arriving on it enter there, and its carrier is the port's link (looked at
    every CARRIER_POLL_NS). Kept apart from the loop's one-link path so that the loop can
    change without it."""

    def __init__(self, link: Link, carrier: Callable[[], bool] | None = None) -> None:
        self.link = link
        self.carrier = carrier
        #: host time of the next look at the carrier
        self.look_ns = 0

    def poll_carrier(self, segment: Segment, now_ns: int) -> None:
        """Give the segment the carrier's state, at most once per CARRIER_POLL_NS."""
        if now_ns < self.look_ns:
            return
        self.look_ns = now_ns + CARRIER_POLL_NS
        segment.set_out_link(self.carrier() if self.carrier is not None else True)


class Daemon:
    """Serve one link (and an out link) with one segment until stopped."""

    def __init__(
        self,
        link: Link,
        segment: Segment,
        *,
        busy_poll: bool = False,
        trace_frames: bool = False,
        ctl: ControlServer | None = None,
        faults: FaultEngine | None = None,
        doors: DoorHost | None = None,
        out: OutPort | None = None,
        logs: LogQueue | None = None,
    ) -> None:
        self.ctl = ctl
        #: log lines held while the loop serves, written after the replies (decision P37)
        self.logs = logs
        #: the out link (--out-iface), None: the segment ends in this process
        self.out = out
        #: the TMCL and LIN front doors served in the same loop, between frames
        self.doors = doors
        self.link = link
        self.segment = segment
        segment.reply_first = True  # handle_one calls after_reply() once the reply is out
        #: injected faults (segment YAML, control socket); idle unless something is armed
        self.faults = faults if faults is not None else FaultEngine(segment)
        #: replies held back by a delay fault: (due time ns, frame), in due order
        self.delayed: list[tuple[int, bytes]] = []
        self.busy_poll = busy_poll
        self.trace_frames = trace_frames
        self.recorder = FrameRecorder()
        #: the per-frame sequence, the same the compiled responder runs (decision P21)
        self.sequence = FrameSequence(segment, self.recorder, link.ethernet)
        #: serve with the compiled responder where it applies (a raw link, the OS clock);
        #: tests compare it with the Python path
        self.compiled = True
        #: the compiled responder serving the link (decision P9), made on first use
        self._responder: ResponderType | None = None
        #: runs the daemon on the master's CPU (decision K5); None: stays where it is
        self.follower: CpuFollower | None = None
        #: the follower's descriptor was readable: frames came in on another CPU
        self._follow_due = False
        self.failures = 0
        self.replies = 0
        #: replies the compiled responder sent
        self.compiled_replies = 0
        self._failure_logged: set[str] = set()
        self._stop = False
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._fd = link.fileno()
        #: the descriptors besides the link's that end a wait: wake-up pipe, control
        #: socket, front doors
        ctl_fd = ctl.fileno() if ctl is not None else -1
        doors_fd = doors.fileno() if doors is not None else -1
        self._watch = tuple(f for f in (self._wake_r, ctl_fd, doors_fd) if f >= 0)

    def stop(self) -> None:
        """Ask the loop to return (safe from a signal handler)."""
        self._stop = True
        try:
            os.write(self._wake_w, b"x")
        except OSError:
            pass

    def install_signal_handlers(self) -> None:
        """SIGINT and SIGTERM end the loop cleanly."""

        def handler(signum: int, frame: FrameType | None) -> None:
            self.stop()

        signal.signal(signal.SIGINT, handler)
        signal.signal(signal.SIGTERM, handler)

    def handle_one(self, buf: bytearray) -> bool:
        """Receive and answer one frame if one is waiting; False if none was."""
        n = self.link.recv_into(buf)
        if n <= 0:
            return False
        self.handle_frame(buf, n, self.link.rx_ns)
        return True

    def handle_out(self, buf: bytearray) -> bool:
        """Receive and pass on one frame from the out link if one is waiting."""
        out = self.out
        if out is None:
            return False
        n = out.link.recv_into(buf)
        if n <= 0:
            return False
        self.handle_frame(buf, n, out.link.rx_ns, 1)
        return True

    def handle_frame(self, buf: bytearray, n: int, rx_ns: int, entry: int = 0) -> None:
        """Answer the frame in ``buf[:n]``, received at host time ``rx_ns`` (0: unknown,
        now) on the daemon's link (``entry`` 0) or the out link (1): the per-frame
        sequence (decision P21) with the reply sent here, where faults may alter or hold
        it and a frame trace logs it."""
        if self.trace_frames and ecat_offset(buf, n, self.link.ethernet) >= 0:
            log.debug("frame_in", data=bytes(buf[:n]).hex())
        seq = self.sequence
        t_rx = rx_ns or self.segment.clock.now_ns()
        try:
            code = seq.arrive(buf, n, t_rx, entry)
        except Exception as exc:  # the loop never dies on a frame
            self._failure("process", exc)
            return
        if code == NOT_ECAT:
            return
        self._answer(buf, seq.off, n, code == REPLY, t_rx)

    def _answer(self, buf: bytearray, off: int, n: int, reply: bool, t_rx: int) -> None:
        """Send the processed frame (unless it is destroyed), then the work after it."""
        link = self.link
        out = self.out
        if out is not None and self.segment.exit:
            link = out.link  # it leaves at the out port
        faults = self.faults
        if reply:
            copies = 1
            if faults.wire_live:
                copies, delay_ns = faults.on_reply(buf, off, n)
                if delay_ns and copies:
                    self._hold(bytes(buf[:n]), copies, delay_ns)
                    copies = 0
            for _ in range(copies):
                link.send(memoryview(buf)[:n])
            self.replies += 1
            # let a master woken on this CPU take the reply before the slaves react
            os.sched_yield()
            if self.trace_frames:
                log.debug("frame_out", data=bytes(buf[:n]).hex())
        self._after(t_rx)

    def _after(self, t_rx: int) -> None:
        """The sequence's steps after the reply: the frame's DC time loops (decision P7),
        the firmware and the timers due by its arrival; then time-triggered faults."""
        seg = self.segment
        seq = self.sequence
        try:
            seq.after()
        except Exception as exc:
            self._failure("process", exc)
        try:
            seq.service(t_rx)
        except Exception as exc:
            self._failure("service", exc)
        follower = self.follower
        if follower is not None and (self._follow_due or 0 < follower.look_ns <= t_rx):
            self._follow(t_rx)
        faults = self.faults
        if faults.active:
            try:
                faults.after_frame(seg.clock.now_ns())
            except Exception as exc:
                self._failure("faults", exc)

    def _follow(self, now_ns: int) -> int:
        """Move to the CPU the master's frames come from (decision K5), after frames came
        in on another CPU (the follower's descriptor was readable) or at the time the
        follower asked to look again. Returns that time (0: none)."""
        follower = self.follower
        self._follow_due = False
        if follower is None:
            return 0
        pauses = follower.pauses
        try:
            cpu = follower.poll(now_ns)
        except OSError as exc:
            log.warning("follow_master_cpu_failed", reason=exc.strerror)
            return follower.look_ns
        if cpu is not None:
            (log.info if follower.moves == 1 else log.debug)("following_master_cpu", cpu=cpu)
        elif follower.pauses != pauses:
            log.info("follow_master_cpu_paused", reason="the master keeps moving away")
        return follower.look_ns

    def _hold(self, frame: bytes, copies: int, delay_ns: int) -> None:
        """A delay fault: send ``frame`` later (``copies`` times)."""
        due = self.segment.clock.now_ns() + delay_ns
        for _ in range(copies):
            self.delayed.append((due, frame))
        self.delayed.sort(key=lambda d: d[0])

    def _send_delayed(self, now_ns: int) -> None:
        while self.delayed and self.delayed[0][0] <= now_ns:
            _, frame = self.delayed.pop(0)
            self.link.send(memoryview(frame))

    def _service(self, t_ns: int | None = None) -> None:
        try:
            self.segment.service(t_ns)
        except Exception as exc:
            self._failure("service", exc)

    def _failure(self, where: str, exc: Exception) -> None:
        self.failures += 1
        key = f"{where}:{type(exc).__name__}:{exc}"
        if key in self._failure_logged:
            return
        self._failure_logged.add(key)
        log.error(
            "frame_failure",
            where=where,
            error=repr(exc),
            count=self.failures,
            last_frames=self.recorder.hexdump(),
            exc_info=exc,
        )

    def run(self) -> None:
        """Serve until stop() is called."""
        buf = bytearray(MAX_FRAME)
        fine_timer_slack()
        logs = self.logs
        if logs is not None:
            logs.active = True  # lines are held while frames are served (decision P37)
            self.segment.schedule.held_logs = logs.held
            self.segment.schedule.write_logs = logs.drain
        try:
            if self.responder_applies():
                self._run_compiled(buf)
            else:
                self._run_select(buf)
        finally:
            if logs is not None:
                logs.active = False
                logs.drain()

    def _write_logs(self) -> None:
        """Write the held log lines, stopping for a frame that waits and firing the SYNC
        pulses that fall due meanwhile (decision P37)."""
        logs = self.logs
        if logs is not None and logs.held:
            self.segment.schedule.write_held_logs()

    def responder_applies(self) -> bool:
        """The compiled responder can serve this link: it was built, the link is a raw
        socket (one frame per receive and per send) and the segment runs on the OS
        monotonic clock the receive time stamps are converted to."""
        return (
            responder is not None
            and self.compiled
            and getattr(self.link, "raw_socket", False)
            and (self.out is None or getattr(self.out.link, "raw_socket", False))
            and isinstance(self.segment.clock, MonotonicClock)
        )

    def _out_fd(self) -> int:
        """The out link's descriptor (-1: none)."""
        return self.out.link.fileno() if self.out is not None else -1

    def frame_fds(self) -> tuple[int, ...]:
        """The descriptors frames arrive on: the daemon's link and the out link."""
        return tuple(f for f in (self._fd, self._out_fd()) if f >= 0)

    def probe_frames(self) -> None:
        """The select(2) loop's probes: the work after a reply stops for a frame that came
        meanwhile on either link (decision P19; on the out link the frame coming back from
        the next daemon, which the master waits for: L9), and pulses fall due on the
        segment's clock (P30). Not for busy-poll, which looks after every piece anyway."""
        fds = self.frame_fds()
        if self._fd < 0 or self.busy_poll:
            return
        self.segment.schedule.frame_waiting = lambda: bool(select.select(fds, (), (), 0)[0])
        self.segment.schedule.now_ns = self.segment.clock.now_ns

    def _run_select(self, buf: bytearray) -> None:
        follow_fd = self.follower.fileno() if self.follower is not None else -1
        self.probe_frames()
        watch = [f for f in (*self.frame_fds(), *self._watch, follow_fd) if f >= 0]
        clock = self.segment.clock
        while not self._stop:
            if self.busy_poll:
                if not (self.handle_one(buf) or self.handle_out(buf)):
                    self._service_timers()
                continue
            deadline = self._deadline()
            timeout = IDLE_TIMEOUT_NS / 1e9
            if deadline is not None:
                timeout = max(0.0, min(timeout, (deadline - clock.now_ns()) / 1e9))
            # select(2), not poll(2): poll's timeout is in whole milliseconds, which would
            # wake the loop up to 1 ms after a SYNC0 deadline (decision P1)
            ready, _, _ = select.select(watch, (), (), timeout)
            self._serve_others(ready)
            if follow_fd in ready:
                self._follow_due = True  # after the frame that came with it (_after)
            # frames first (one that came in since poll returned is older than "now"), then
            # the timers: every frame is served before the pulses that come after it
            while self.handle_one(buf) or self.handle_out(buf):
                pass
            if self._follow_due:  # no frame came with it
                self._follow(clock.now_ns())
            self._service_timers()

    def _run_compiled(self, buf: bytearray) -> None:
        """The loop with the compiled responder (decision P9): it serves frames and the
        segment's timers itself and comes back for the deadlines and descriptors that
        Python serves."""
        clock = self.segment.clock
        srv = self._make_responder()
        # the work after a reply stops for a frame that came meanwhile (decision P19)
        self.segment.schedule.frame_waiting = srv.frame_waiting
        self.segment.schedule.now_ns = clock.now_ns  # pulses due meanwhile (decision P30)
        while not self._stop:
            fast = self._fast_ok()
            now = clock.now_ns()
            deadline = self._deadline(segment=not fast)
            if deadline is None or deadline - now > IDLE_TIMEOUT_NS:
                deadline = now + IDLE_TIMEOUT_NS
            self.serve_once(buf, deadline, timers=fast)

    def serve_once(
        self, buf: bytearray, deadline_ns: int, t_rx_ns: int = 0, timers: bool = False
    ) -> int:
        """One call of the compiled responder: wait until a frame arrives, ``deadline_ns``
        (host monotonic) passes or another descriptor is readable, and serve what came. A
        frame waiting is always served before the timers, as in :meth:`_run_select`.
        ``t_rx_ns``: the frame's arrival time (0: the kernel's receive time stamp).
        ``timers``: the responder also runs the segment's timers and goes on serving
        until ``deadline_ns`` (the segment on the OS clock; else one frame at most).
        Returns the responder's code (``responder.REPLIED`` ...) for the last thing done."""
        mod = responder
        assert mod is not None
        srv = self._make_responder()
        follower = self.follower
        if follower is not None:
            srv.set_follow(self._follow, follower.fileno(), follower.look_ns)
        else:
            srv.set_follow(None, -1, 0)
        seq = self.sequence if self._fast_ok() else None
        before = srv.replied
        n = t_rx = 0
        try:
            code, n, t_rx = srv.serve(buf, deadline_ns, seq, t_rx_ns, timers and seq is not None)
        except mod.SegmentError as exc:  # the loop never dies on a frame
            self._failure("process", exc.__cause__ or exc)
            code = mod.DROPPED  # handled: by a failure, as in handle_frame
        except mod.ServiceError as exc:  # nor on the work after it
            where, t, code = exc.args
            self._failure(where, exc.__cause__ or exc)
            if where == "process":
                self._service(t)  # what _after runs after a failed after_reply
        finally:
            sent = srv.replied - before
            self.replies += sent
            self.compiled_replies += sent
        if code == mod.FRAME:
            self.handle_frame(buf, n, t_rx, srv.entry)
        elif code in (mod.TIMEOUT, mod.WAKE):
            if code == mod.WAKE:
                ready, _, _ = select.select(self._watch, (), (), 0)
                self._serve_others(ready)
            self._service_timers()
        return int(code)

    def reply_times(self) -> dict[str, int]:
        """The daemon's own reply times, from each frame's kernel receive time stamp to
        after its reply's send (decision B9): measured by the compiled responder, {} when
        it has served no frame."""
        srv = self._responder
        return srv.reply_times() if srv is not None and srv.replied else {}

    def _make_responder(self) -> ResponderType:
        """The compiled responder serving the link, made on first use."""
        mod = responder
        assert mod is not None
        srv = self._responder
        if srv is None:
            srv = self._responder = mod.Responder(
                self._fd, self._watch, self.recorder, self.busy_poll, out_fd=self._out_fd()
            )
        return srv

    def _fast_ok(self) -> bool:
        """The compiled responder may serve frames whole: nothing that watches or alters
        them (frame trace, injected faults) is on, and the daemon sends each reply before
        the segment's work after it (decision P7)."""
        return (
            self.segment.compiled
            and self.segment.reply_first
            and not self.trace_frames
            and not self.faults.active
            and not self.faults.wire_live
        )

    def _serve_others(self, ready: list[int]) -> None:
        """The wake-up pipe and the control socket, when readable."""
        for efd in ready:
            if efd == self._wake_r:
                try:
                    os.read(self._wake_r, 64)
                except OSError:
                    pass
            elif self.ctl is not None and efd == self.ctl.fileno():
                try:
                    self.ctl.serve()
                except Exception as exc:
                    self._failure("ctl", exc)
            elif self.doors is not None and efd == self.doors.fileno():
                self.doors.serve()  # a door's failure is counted by the host

    def _deadline(self, segment: bool = True) -> int | None:
        """The earliest deadline of the loop's timers; ``segment``: the segment's too."""
        ds = [
            d
            for d in (
                self.segment.schedule.next_deadline() if segment else None,
                self.faults.next_deadline(),
            )
            if d is not None
        ]
        if self.delayed:
            ds.append(self.delayed[0][0])
        if self.out is not None:
            ds.append(self.out.look_ns)
        if self.doors is not None:
            d = self.doors.next_deadline()
            if d is not None:
                ds.append(d)
        return min(ds) if ds else None

    def _service_timers(self) -> None:
        """Timers that are due (SYNC pulses, watchdogs), firmware work a control command
        left pending, delayed replies and time-triggered faults."""
        seg = self.segment
        ctx = seg.ctx
        if self.out is not None:
            self.out.poll_carrier(seg, seg.clock.now_ns())
        d = seg.schedule.next_deadline()
        if ctx.pending or ctx.flush or (d is not None and d <= seg.clock.now_ns()):
            self._service()
        doors = self.doors
        if doors is not None:
            d = doors.next_deadline()
            if d is not None and d <= seg.clock.now_ns():
                doors.service(seg.clock.now_ns())
        if self.delayed or self.faults.active:
            now = self.segment.clock.now_ns()
            self._send_delayed(now)
            if self.faults.active:
                try:
                    self.faults.poll(now)
                except Exception as exc:
                    self._failure("faults", exc)
        self._write_logs()

    def close(self) -> None:
        self.link.close()
        if self.out is not None:
            self.out.link.close()
        if self.follower is not None:
            self.follower.close()
        if self._responder is not None:
            self._responder.close()
        for f in (self._wake_r, self._wake_w):
            try:
                os.close(f)
            except OSError:
                pass
