"""The compiled responder (decision P9): its wait (the deadline, the other descriptors,
the busy mode), a frame handed over untouched, every kind of frame served through the
per-frame sequence it shares with Daemon.handle_frame (decision P21), and Daemon.run
serving through it.
Ref: ecatsim/ethercat/responder.pyx; ecatsim/ethercat/daemon.py Daemon.serve_once,
Daemon.handle_frame."""

from __future__ import annotations

import os
import socket
import struct
import threading
import time
from collections.abc import Iterator
from types import ModuleType
from typing import Any

import pytest

from ecatsim.clock import MonotonicClock
from ecatsim.ethercat import daemon as daemon_mod
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.daemon import Daemon, OutPort
from ecatsim.ethercat.prefetch import hot_lines
from ecatsim.ethercat.recorder import FrameRecorder
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig
from ecatsim.ethercat.sequence import FrameSequence
from ecatsim.link.raw import SO_TIMESTAMPNS
from ecatsim.wire import datagram as dg
from tests.perf.hotpath import IN, MS, OUT, CspCycle
from tests.support.compiled import record_results, require_built
from tests.support.socketlink import SocketLink
from tests.support.tinymaster import segment_of

TIMEOUT, WAKE, FRAME, REPLIED, DROPPED = 0, 1, 2, 3, 4


@pytest.fixture
def srv() -> ModuleType:
    require_built(daemon_mod.responder, "ecatsim.ethercat.responder")
    assert daemon_mod.responder is not None
    return daemon_mod.responder


@pytest.fixture
def link() -> Iterator[SocketLink]:
    s = SocketLink()
    yield s
    s.close()


def test_codes(srv: ModuleType) -> None:
    assert (srv.TIMEOUT, srv.WAKE, srv.FRAME, srv.REPLIED, srv.DROPPED) == (
        TIMEOUT,
        WAKE,
        FRAME,
        REPLIED,
        DROPPED,
    )


def responder_on(srv: ModuleType, link: SocketLink, others: tuple[int, ...] = (),
                 busy: bool = False, timer: bool = True) -> Any:  # fmt: skip
    return srv.Responder(link.fileno(), others, FrameRecorder(), busy, timer)


@pytest.mark.parametrize(("busy", "timer"), [(False, False), (False, True), (True, False)])
def test_waits_until_the_deadline(
    srv: ModuleType, link: SocketLink, busy: bool, timer: bool
) -> None:
    """The wait ends at the deadline: a ppoll timeout, the timer fd (armed once per
    deadline, so a second wait for the same deadline must still end), or spinning."""
    r = responder_on(srv, link, busy=busy, timer=timer)
    try:
        buf = bytearray(2048)
        for _ in range(2):
            t0 = time.monotonic_ns()
            deadline = t0 + 20_000_000
            code, n, _t = r.serve(buf, deadline)
            waited = time.monotonic_ns() - t0
            assert (code, n) == (TIMEOUT, 0)
            assert 20_000_000 <= waited < 2_000_000_000  # a wide guard, not a timing test
        # the same deadline again, now passed: no wait at all
        code, *_ = r.serve(buf, deadline)
        assert code == TIMEOUT
    finally:
        r.close()


def test_timer_armed_once_per_deadline(srv: ModuleType, link: SocketLink) -> None:
    """A wait that another descriptor ended leaves the timer armed: the next wait for the
    same deadline is not re-armed and still ends at it."""
    r, w = os.pipe()
    resp = responder_on(srv, link, (r,))
    try:
        buf = bytearray(2048)
        deadline = time.monotonic_ns() + 30_000_000
        os.write(w, b"x")
        code, *_ = resp.serve(buf, deadline)
        assert code == WAKE
        os.read(r, 1)
        code, *_ = resp.serve(buf, deadline)
        assert code == TIMEOUT
        assert deadline <= time.monotonic_ns() < deadline + 2_000_000_000
    finally:
        resp.close()
        for f in (r, w):
            os.close(f)


def test_a_frame_ends_a_timer_wait(srv: ModuleType, link: SocketLink) -> None:
    """Blocked on the timer fd with a far deadline, a frame from another thread ends the
    wait at once."""
    resp = responder_on(srv, link)
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    sender = threading.Timer(0.05, link.master_send, (frame,))
    try:
        sender.start()
        t0 = time.monotonic_ns()
        code, n, _t = resp.serve(bytearray(2048), t0 + 10**10)
        assert (code, n) == (FRAME, len(frame))
        assert time.monotonic_ns() - t0 < 5 * 10**9
    finally:
        sender.join()
        resp.close()


@pytest.mark.parametrize("busy", [False, True])
def test_another_descriptor_ends_the_wait(srv: ModuleType, link: SocketLink, busy: bool) -> None:
    r, w = os.pipe()
    resp = responder_on(srv, link, (r,), busy=busy, timer=False)
    try:
        os.write(w, b"x")
        t0 = time.monotonic_ns()
        code, _n, _t = resp.serve(bytearray(64), t0 + 10**10)
        assert code == WAKE
        assert time.monotonic_ns() - t0 < 5 * 10**9
    finally:
        os.close(r)
        os.close(w)


def test_a_frame_waiting_comes_before_the_deadline(srv: ModuleType, link: SocketLink) -> None:
    """Without a segment the frame is handed over as received, with its arrival time."""
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    link.master_send(frame)
    buf = bytearray(2048)
    rec = FrameRecorder()
    resp = srv.Responder(link.fileno(), (), rec, False, False)
    before = time.monotonic_ns()
    code, n, t_rx = resp.serve(buf, 0)
    assert (code, n) == (FRAME, len(frame))
    assert bytes(buf[:n]) == frame
    assert before - 10**9 < t_rx <= time.monotonic_ns()
    assert rec.last() == []  # nothing served, nothing kept
    assert link.master_recv() is None  # nothing sent


def test_bad_arguments_raise(srv: ModuleType, link: SocketLink) -> None:
    resp = responder_on(srv, link, timer=False)
    for bad in (bytes(64), None):
        with pytest.raises(TypeError):
            resp.serve(bad, 0)
    with pytest.raises(TypeError):
        srv.Responder(link.fileno(), (), None)
    with pytest.raises(ValueError):
        srv.Responder(link.fileno(), tuple(range(9)), FrameRecorder())
    with pytest.raises(ValueError):
        resp.serve(bytearray(64), 0, None, 0, True)  # the segment's timers need a segment


def pair_of_cycles() -> tuple[CspCycle, CspCycle]:
    """Two identical drives in OP with SYNC0 running: one served by the responder over a
    socket pair, one by Daemon.handle_frame over a loopback link."""
    return CspCycle(1, responder=True), CspCycle(1)


def state(c: CspCycle) -> tuple[object, ...]:
    """What serving a frame leaves behind: the reply counters, the recorder, the segment's
    counters, pending DC work, SYNC pulses and the ESC's memory."""
    seg, d = c.seg, c.daemon
    return (
        d.replies,
        d.failures,
        d.recorder.last(),
        seg.frames,
        seg.bad_frames,
        seg.ctx.frame_no,
        seg.ctx.t_ns,
        seg._dc_pending,
        seg.schedule.sync0_ticks,
        bytes(seg.escs[0].mem),
    )


def other_frames(c: CspCycle) -> list[bytes]:
    """Frames beside the cyclic one: a broadcast read, a write of the AL control register,
    the cyclic frame behind an 802.1Q tag, a truncated frame and a too-long datagram
    (destroyed), a header of another type (sent back unprocessed), a frame too short for
    an EtherCAT header (ignored)."""
    cyclic = c.frame(0x0F)
    return [
        cyclic[:12] + b"\x81\x00\x00\x05" + cyclic[12:],
        dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))]),
        dg.ethernet_frame([dg.build(dg.Cmd.APWR, 0, 0x0120, b"\x08\x00")]),
        cyclic[:40],
        cyclic[:14] + bytes([0xFF, 0x17]) + cyclic[16:],
        cyclic[:15] + bytes([0x50]) + cyclic[16:],
        cyclic[:15],
    ]


def test_responder_serves_every_kind_of_frame(
    srv: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Frames through the responder (serve_once): cyclic frames, some with a SYNC0 pulse
    still due, and the other kinds: each is answered, destroyed or handed to Python as the
    per-frame sequence says (decision P21), every reply sent by the responder."""
    answered = record_results(monkeypatch, daemon_mod, "responder", "Responder", "serve")
    a, _ = pair_of_cycles()
    answered.clear()  # the constructor's cycles
    assert a.daemon._fast_ok()
    replies = []
    for k in range(12):
        if k % 4:
            a.pulse()  # every fourth frame finds its pulse still due
        a.clock.t = a.t + MS // 2
        frames = [a.frame(0x0F), *(other_frames(a) if k == 5 else ())]
        for raw in frames:
            replies.append(a.deliver(raw))
        a.t += MS
    assert a.daemon.compiled_replies == a.daemon.replies, "every reply sent by the responder"
    codes = [r[0] for r in answered]
    assert (codes.count(REPLIED), codes.count(DROPPED), codes.count(FRAME)) == (12 + 4, 2, 1)
    assert sum(r is not None for r in replies) == 12 + 4
    cyclic = [r for r in replies if r is not None and len(r) == len(a.frame(0x0F))]
    assert all(r[6] & 0x02 for r in cyclic)  # processed: the source MAC bit


def test_a_traced_daemon_serves_in_python(srv: ModuleType) -> None:
    """With the frame trace on (or a fault armed) the responder hands every frame to
    Daemon.handle_frame untouched, and the replies are the same."""
    a, b = pair_of_cycles()
    a.daemon.trace_frames = True
    assert not a.daemon._fast_ok()
    served = a.daemon.compiled_replies  # the constructor's cycles
    for _ in range(3):
        assert a.step() == b.step()
    assert (a.daemon.compiled_replies, a.daemon.replies) == (served, served + 3)
    assert state(a)[1:] == state(b)[1:]


class Failing(Segment):
    """A segment whose frame processing fails."""

    def process(self, buf: bytearray, off: int, n: int, t_ns: int = 0, entry: int = 0) -> bool:
        raise RuntimeError("broken segment")


def test_a_failing_frame_is_counted_as_in_handle_frame(srv: ModuleType, link: SocketLink) -> None:
    """The segment raises while processing: the daemon counts and logs the failure with the
    frame recorded, sends nothing and carries on, as handle_frame does."""
    seg, _ = segment_of(1)
    failing = Failing(seg.escs, seg.ctx, MonotonicClock())
    d = Daemon(link, failing)
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    link.master_send(frame)
    assert d.serve_once(bytearray(2048), time.monotonic_ns() + 10**9) == DROPPED
    assert (d.failures, d.replies, d.recorder.last()) == (1, 0, [frame])
    assert link.master_recv() is None
    with pytest.raises(srv.SegmentError) as err:
        link.master_send(frame)
        srv.Responder(link.fileno(), (), FrameRecorder(), False, False).serve(
            bytearray(2048), 0, FrameSequence(failing, FrameRecorder())
        )
    assert isinstance(err.value.__cause__, RuntimeError)
    assert err.value.args == (len(frame),)


def test_daemon_run_serves_through_the_responder(srv: ModuleType, link: SocketLink) -> None:
    """Daemon.run on a raw-socket link and the OS clock: a logical frame and a broadcast
    read are answered by the responder, and stop() ends the loop from another thread."""
    seg = build_segment(SegmentConfig((SlaveConfig(device="echo", serial=1),)), MonotonicClock())
    d = Daemon(link, seg)
    assert d.responder_applies()
    t = threading.Thread(target=d.run)
    t.start()
    try:
        lrd = dg.ethernet_frame([dg.build_logical(dg.Cmd.LRD, 0, bytes(4))])
        brd = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
        replies = []
        for frame in (lrd, brd, lrd):
            link.master_send(frame)
            deadline = time.monotonic() + 5
            reply = None
            while reply is None and time.monotonic() < deadline:
                time.sleep(0.001)
                reply = link.master_recv()
            replies.append(reply)
    finally:
        d.stop()
        t.join(5)
    assert not t.is_alive()
    # LRD with no FMMU: WKC 0, the processed bit set; BRD of the AL status: 0x0001, WKC 1
    processed = bytearray(lrd)
    processed[6] |= 0x02
    assert replies[0] == bytes(processed) and replies[2] == bytes(processed)
    assert replies[1] is not None and replies[1][26:30] == b"\x01\x00\x01\x00"
    assert (d.replies, d.compiled_replies, d.failures) == (3, 3, 0)


def test_the_responder_serves_the_out_link_too(srv: ModuleType, link: SocketLink) -> None:
    """With an out link (decision L9) the responder waits on both links: a frame from the
    master leaves on the out link marked processed, the same frame coming back there
    leaves on the daemon's link unchanged, both served compiled; the work after a reply
    stops for a frame waiting on either link."""
    cfg = SegmentConfig(tuple(SlaveConfig(device="echo", serial=i + 1) for i in range(2)))
    seg = build_segment(cfg, MonotonicClock(), out=True)
    far = SocketLink()
    try:
        d = Daemon(link, seg, out=OutPort(far, lambda: True))
        assert d.responder_applies()
        d._service_timers()  # the first look at the carrier
        assert seg.out_up
        buf = bytearray(2048)
        frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
        link.master_send(frame)
        deadline = time.monotonic_ns() + 1_000_000_000
        assert d.serve_once(buf, deadline) == srv.REPLIED
        went = far.master_recv()
        assert link.master_recv() is None and went is not None
        processed = bytearray(frame)
        processed[6] |= 0x02
        processed[18] = 2  # each slave counts the position up
        processed[26:30] = b"\x01\x00\x02\x00"  # both AL status INIT, WKC 2
        assert went == processed
        far.master_send(went)  # the next daemon's reply comes back on the out link
        assert d.serve_once(buf, deadline) == srv.REPLIED
        assert link.master_recv() == went and far.master_recv() is None
        assert (d.replies, d.compiled_replies, d.failures) == (2, 2, 0)
        waiting = d._make_responder().frame_waiting
        assert not waiting()
        far.master_send(b"\x00" * 60)
        assert waiting()
    finally:
        far.close()


def test_the_responder_runs_the_segments_timers(
    srv: ModuleType, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With ``timers`` (the daemon on the OS clock) one call serves the SYNC0 pulses as
    they fall due and a frame that comes meanwhile, and returns only at the daemon's own
    deadline: Python's timers run once, after it."""
    c = CspCycle(1, enable=False, responder=True, clock=MonotonicClock())
    d = c.daemon
    python_timers: list[int] = []
    monkeypatch.setattr(d, "_service_timers", lambda: python_timers.append(1))
    ticks, replies = c.seg.schedule.sync0_ticks, d.replies
    frame = c.frame(0x00)
    sender = threading.Timer(0.02, c.link.master_send, (frame,))
    t0 = time.monotonic_ns()
    sender.start()
    try:
        code = d.serve_once(c.buf, t0 + 50 * MS, timers=True)
    finally:
        sender.join()
    assert code == TIMEOUT
    assert time.monotonic_ns() - t0 >= 50 * MS
    # about 48 pulses of 1 ms from 2 ms on; a wide guard, not a timing test
    assert c.seg.schedule.sync0_ticks - ticks >= 20
    assert (d.replies - replies, d.compiled_replies - replies) == (1, 1)
    reply = c.link.master_recv()
    assert reply is not None and reply[6] & 0x02  # processed
    lrw_wkc = 14 + 2 + 10 + OUT + IN  # the LRW's WKC: outputs written, inputs read
    assert struct.unpack_from("<H", reply, lrw_wkc)[0] == 3
    assert d.recorder.last()[-1] == frame
    assert python_timers == [1]


class FailingService(Segment):
    """A segment whose work after a reply fails."""

    def service_at(self, t: int) -> None:  # Segment.service and the responder's call
        raise RuntimeError("broken firmware")


def test_a_failing_service_is_counted_and_the_loop_goes_on(
    srv: ModuleType, link: SocketLink
) -> None:
    """The work after a reply raises in the responder: the reply is out, the daemon counts
    and logs the failure once, and the next frame is served."""
    seg, _ = segment_of(1)
    failing = FailingService(seg.escs, seg.ctx, MonotonicClock())
    d = Daemon(link, failing)
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    for k in range(2):
        link.master_send(frame)
        assert d.serve_once(bytearray(2048), time.monotonic_ns() + 10**9) == REPLIED
        reply = link.master_recv()
        assert reply is not None and reply[26:30] == b"\x01\x00\x01\x00"  # INIT, WKC 1
        assert (d.replies, d.failures) == (k + 1, k + 1)
    assert d.recorder.last() == [frame, frame]


class PipeFollower:
    """A CPU follower (decision K5) whose descriptor is a pipe the test writes to, as the
    probes' epoll set becomes readable when a frame comes in on another CPU; ``poll``
    records its calls and drains the pipe, as the real one drains its probes, and stops
    the following for ``stop_ns`` if set (as a pause does: nothing watched, a look at
    ``look_ns``)."""

    pauses = moves = 0

    def __init__(self) -> None:
        self.r, self.w = os.pipe()
        os.set_blocking(self.r, False)
        self.look_ns = 0
        self.stop_ns = 0
        self.calls: list[int] = []

    def fileno(self) -> int:
        return self.r

    def poll(self, now_ns: int) -> int | None:
        self.calls.append(now_ns)
        self.look_ns = now_ns + self.stop_ns if self.stop_ns else 0
        self.stop_ns = 0
        try:
            os.read(self.r, 64)
        except BlockingIOError:
            pass
        return None

    def close(self) -> None:
        os.close(self.r)
        os.close(self.w)


@pytest.mark.parametrize("compiled", [True, False])
def test_the_cpu_following_runs_only_when_its_descriptor_or_time_says_so(
    compiled: bool, link: SocketLink
) -> None:
    """Frames on the daemon's own CPU cost nothing for the following: its poll runs after a
    frame only once the follower's descriptor is readable (a frame came in elsewhere), at
    once if no frame comes with it, and after a frame arriving at its ``look_ns`` or later
    (the following stopped until then). Through Daemon.run: the compiled responder and the
    select(2) loop."""
    if compiled:
        require_built(daemon_mod.responder, "ecatsim.ethercat.responder")
    seg = build_segment(SegmentConfig((SlaveConfig(device="echo", serial=1),)), MonotonicClock())
    d = Daemon(link, seg)
    d.compiled = compiled
    assert d.responder_applies() == compiled
    f = PipeFollower()
    d.follower = f  # type: ignore[assignment]
    brd = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])

    def exchange() -> None:
        link.master_send(brd)
        deadline = time.monotonic() + 5
        while link.master_recv() is None:
            assert time.monotonic() < deadline, "no reply"
            time.sleep(0.001)

    def calls_become(n: int) -> None:
        deadline = time.monotonic() + 5
        while len(f.calls) < n and time.monotonic() < deadline:
            time.sleep(0.001)
        time.sleep(0.05)  # and no more come
        assert len(f.calls) == n

    t = threading.Thread(target=d.run)
    t.start()
    try:
        for _ in range(3):
            exchange()
        calls_become(0)
        os.write(f.w, b"x")  # with the next frame
        exchange()
        calls_become(1)
        exchange()
        calls_become(1)
        f.stop_ns = 200 * MS
        os.write(f.w, b"x")  # no frame comes with it
        calls_become(2)
        exchange()  # stopped: no look before look_ns
        calls_become(2)
        time.sleep(0.25)
        exchange()
        calls_become(3)
        assert f.calls[2] >= f.calls[1] + 200 * MS
        exchange()
        calls_become(3)
    finally:
        d.stop()
        t.join(5)
        f.close()
    assert not t.is_alive()
    assert d.failures == 0


def test_hot_lines_name_what_a_cyclic_frame_reads() -> None:
    """hot_lines (the responder's prefetch at each wake-up, decision P18): each
    ESC with its DC unit, watchdog and FMMU maps, the SMs they map with their three buffers,
    and the event, AL event, SM and DC register lines, every range inside the memory."""
    c = CspCycle(2)
    c.step()
    objs, ranges = hot_lines(c.seg)
    for esc in c.seg.escs:
        assert all(any(o is x for o in objs) for x in (esc, esc.dc, esc.wd, esc.mem))
        mapped = [f.sm for f in esc.fmmus if f.sm is not None]
        assert {sm.n for sm in mapped} == {2, 3}  # outputs and inputs
        for sm in mapped:
            assert any(o is sm for o in objs)
            assert (esc.mem, sm.start, sm.start + 3 * sm.length) in ranges
        mine = [(a, b) for m, a, b in ranges if m is esc.mem]
        assert (0x0200, 0x0240) in mine and (0x0900, 0x0940) in mine
        assert all(0 <= a < b <= len(esc.mem) for a, b in mine)


def test_the_responder_times_its_own_replies(srv: ModuleType, link: SocketLink) -> None:
    """Decision B9: from each frame's kernel receive time stamp to after its reply's send.
    A frame served at once counts in none of the late counts; one left 3 ms in the
    socket counts as a reply of 1 ms and 2 ms or more that waited 1 ms or more before
    its processing; a frame whose arrival time the caller gives (a manual clock) is not
    timed. The daemon's ``reply_times`` are the responder's."""
    link.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    seg = build_segment(SegmentConfig((SlaveConfig(device="echo", serial=1),)), MonotonicClock())
    d = Daemon(link, seg)
    assert d.reply_times() == {}  # no responder yet
    brd = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    buf = bytearray(2048)
    link.master_send(brd)
    assert d.serve_once(buf, time.monotonic_ns() + 10**9) == REPLIED
    first = d.reply_times()
    assert first["replies_over_1ms"] == first["replies_over_2ms"] == 0, first
    assert first["late_picked_up_late"] == 0
    assert 0 <= first["pickup_max_us"] <= first["reply_max_us"] < 1000
    link.master_send(brd)
    time.sleep(0.003)  # the frame waits in the socket
    assert d.serve_once(buf, time.monotonic_ns() + 10**9) == REPLIED
    late = d.reply_times()
    assert (late["replies_over_1ms"], late["replies_over_2ms"], late["late_picked_up_late"]) == (
        1,
        1,
        1,
    )
    assert 3000 <= late["pickup_max_us"] <= late["reply_max_us"] < 10**6
    link.master_send(brd)
    time.sleep(0.003)
    assert d.serve_once(buf, time.monotonic_ns() + 10**9, t_rx_ns=time.monotonic_ns()) == REPLIED
    assert d.reply_times() == late  # given an arrival time: not timed
    assert d.replies == 3
    for _ in range(3):
        assert link.master_recv() is not None
