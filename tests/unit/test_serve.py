"""The compiled responder's wait (decision P9): the deadline, the other descriptors, the
busy mode, a frame handed over untouched, and Daemon.run serving through it. What it does
to frames is compared with Python in tests/unit/slave/test_cycle_compiled.py.
Ref: ecatsim/_serve.c; ecatsim/daemon.py Daemon.serve_once."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from types import ModuleType

import pytest

from ecatsim import daemon as daemon_mod
from ecatsim.build import build_segment
from ecatsim.clock import MonotonicClock
from ecatsim.config import SegmentConfig, SlaveConfig
from ecatsim.daemon import Daemon
from ecatsim.wire import datagram as dg
from tests.support.compiled import require_built
from tests.support.socketlink import SocketLink

TIMEOUT, WAKE, FRAME, REPLIED, RESUME = 0, 1, 2, 3, 4


@pytest.fixture
def srv() -> ModuleType:
    require_built(daemon_mod._serve, "ecatsim._serve")
    assert daemon_mod._serve is not None
    return daemon_mod._serve


@pytest.fixture
def link() -> Iterator[SocketLink]:
    s = SocketLink()
    yield s
    s.close()


def test_codes(srv: ModuleType) -> None:
    assert (srv.TIMEOUT, srv.WAKE, srv.FRAME, srv.REPLIED, srv.RESUME) == (
        TIMEOUT,
        WAKE,
        FRAME,
        REPLIED,
        RESUME,
    )


@pytest.mark.parametrize(("busy", "timer"), [(False, False), (False, True), (True, False)])
def test_waits_until_the_deadline(
    srv: ModuleType, link: SocketLink, busy: bool, timer: bool
) -> None:
    """The wait ends at the deadline: a ppoll timeout, the timer fd (armed once per
    deadline, so a second wait for the same deadline must still end), or spinning."""
    tfd = srv.timer() if timer else -1
    try:
        buf, copy = bytearray(2048), bytearray(2048)
        for _ in range(2):
            t0 = time.monotonic_ns()
            deadline = t0 + 20_000_000
            code, n, _t, _p = srv.serve(link.fileno(), (), buf, copy, deadline, busy, None, 0, tfd)
            waited = time.monotonic_ns() - t0
            assert (code, n) == (TIMEOUT, 0)
            assert 20_000_000 <= waited < 2_000_000_000  # a wide guard, not a timing test
        # the same deadline again, now passed: no wait at all
        code, *_ = srv.serve(link.fileno(), (), buf, copy, deadline, busy, None, 0, tfd)
        assert code == TIMEOUT
    finally:
        if tfd >= 0:
            os.close(tfd)


def test_timer_armed_once_per_deadline(srv: ModuleType, link: SocketLink) -> None:
    """A wait that another descriptor ended leaves the timer armed: the next wait for the
    same deadline is not re-armed and still ends at it."""
    tfd = srv.timer()
    r, w = os.pipe()
    try:
        buf, copy = bytearray(2048), bytearray(2048)
        deadline = time.monotonic_ns() + 30_000_000
        os.write(w, b"x")
        code, *_ = srv.serve(link.fileno(), (r,), buf, copy, deadline, False, None, 0, tfd)
        assert code == WAKE
        os.read(r, 1)
        code, *_ = srv.serve(link.fileno(), (r,), buf, copy, deadline, False, None, 0, tfd)
        assert code == TIMEOUT
        assert deadline <= time.monotonic_ns() < deadline + 2_000_000_000
    finally:
        for f in (r, w, tfd):
            os.close(f)


def test_a_frame_ends_a_timer_wait(srv: ModuleType, link: SocketLink) -> None:
    """Blocked on the timer fd with a far deadline, a frame from another thread ends the
    wait at once."""
    tfd = srv.timer()
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    sender = threading.Timer(0.05, link.master_send, (frame,))
    try:
        sender.start()
        t0 = time.monotonic_ns()
        code, n, _t, _p = srv.serve(
            link.fileno(), (), bytearray(2048), bytearray(2048), t0 + 10**10, False, None, 0, tfd
        )
        assert (code, n) == (FRAME, len(frame))
        assert time.monotonic_ns() - t0 < 5 * 10**9
    finally:
        sender.join()
        os.close(tfd)


@pytest.mark.parametrize("busy", [False, True])
def test_another_descriptor_ends_the_wait(srv: ModuleType, link: SocketLink, busy: bool) -> None:
    r, w = os.pipe()
    try:
        os.write(w, b"x")
        t0 = time.monotonic_ns()
        code, _n, _t, _p = srv.serve(
            link.fileno(), (r,), bytearray(64), bytearray(64), t0 + 10**10, busy, None, 0, -1
        )
        assert code == WAKE
        assert time.monotonic_ns() - t0 < 5 * 10**9
    finally:
        os.close(r)
        os.close(w)


def test_a_frame_waiting_comes_before_the_deadline(srv: ModuleType, link: SocketLink) -> None:
    """Without a segment the frame is handed over as received, with its arrival time."""
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    link.master_send(frame)
    buf, copy = bytearray(2048), bytearray(2048)
    before = time.monotonic_ns()
    code, n, t_rx, p = srv.serve(link.fileno(), (), buf, copy, 0, False, None, 0, -1)
    assert (code, n, p) == (FRAME, len(frame), 0)
    assert bytes(buf[:n]) == frame
    assert before - 10**9 < t_rx <= time.monotonic_ns()
    assert copy == bytearray(2048)  # nothing processed, nothing kept
    assert link.master_recv() is None  # nothing sent


def test_bad_arguments_raise(srv: ModuleType, link: SocketLink) -> None:
    with pytest.raises(TypeError):
        srv.serve(link.fileno(), (), bytearray(64), bytearray(8), 0, False, None, 0, -1)
    with pytest.raises(ValueError):
        srv.serve(
            link.fileno(), tuple(range(9)), bytearray(64), bytearray(64), 0, False, None, 0, -1
        )
    with pytest.raises(ValueError):
        srv.serve(link.fileno(), (), bytearray(64), bytearray(64), 0, False, None, 0, 1 << 20)


def test_daemon_run_serves_through_the_responder(srv: ModuleType, link: SocketLink) -> None:
    """Daemon.run on a raw-socket link and the OS clock: a logical frame is answered in C,
    a broadcast read by Python, and stop() ends the loop from another thread."""
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
    assert replies[0] == processed and replies[2] == processed
    assert replies[1] is not None and replies[1][26:30] == b"\x01\x00\x01\x00"
    assert (d.replies, d.compiled_replies, d.failures) == (3, 2, 0)
