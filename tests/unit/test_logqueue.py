"""Log lines held while the daemon serves and written after the replies (decision P37)."""

from __future__ import annotations

import io
import json
import logging
import time
from collections.abc import Iterator

import pytest
import structlog

from ecatsim.logqueue import LogQueue
from ecatsim.logsetup import configure_logging
from ecatsim.wire import datagram as dg
from tests.perf.hotpath import op_segment


@pytest.fixture
def out() -> Iterator[io.StringIO]:
    yield io.StringIO()
    structlog.reset_defaults()


def lines(buf: io.StringIO) -> list[dict[str, object]]:
    return [json.loads(x) for x in buf.getvalue().splitlines()]


def test_a_line_is_written_at_once_while_the_queue_is_inactive(out: io.StringIO) -> None:
    q = configure_logging("json", file=out)
    structlog.get_logger("t").info("one", slave=3)
    assert len(q) == 0
    (line,) = lines(out)
    assert (line["event"], line["slave"], line["level"]) == ("one", 3, "info")


def test_held_lines_are_written_in_order_with_the_time_of_the_call(out: io.StringIO) -> None:
    q = configure_logging("json", file=out)
    log = structlog.get_logger("t").bind(slave=7)
    q.active = True
    before = time.time()
    log.info("al_state", state="PREOP")
    log.warning("drive_fault", kind="overcurrent")
    after = time.time()
    assert out.getvalue() == ""
    assert len(q) == 2
    time.sleep(0.05)
    assert q.drain() == 2
    first, second = lines(out)
    assert (first["event"], first["state"], first["slave"]) == ("al_state", "PREOP", 7)
    assert (second["event"], second["level"]) == ("drive_fault", "warning")
    for line in (first, second):
        stamp = str(line["timestamp"])
        assert stamp.endswith("Z") and "_held_at" not in line
        t = time.mktime(time.strptime(stamp[:19], "%Y-%m-%dT%H:%M:%S")) - time.timezone
        assert before - 1 <= t <= after  # the call's time, not the drain's 50 ms later
    assert len(q) == 0


def test_the_time_stamp_is_structlogs_iso_utc_format(out: io.StringIO) -> None:
    configure_logging("json", file=out)
    structlog.get_logger("t").info("x")
    ours = str(lines(out)[0]["timestamp"])
    theirs = structlog.processors.TimeStamper(fmt="iso", utc=True)(None, "info", {})["timestamp"]
    assert len(ours) == len(theirs) and ours[10] == theirs[10] == "T" and ours[-1] == "Z"


def test_a_traceback_is_written_at_once_after_the_lines_held_before_it(
    out: io.StringIO,
) -> None:
    q = configure_logging("json", file=out)
    log = structlog.get_logger("t")
    q.active = True
    log.info("held")
    try:
        raise ValueError("boom")
    except ValueError as exc:
        log.error("frame_failure", exc_info=exc)
    assert len(q) == 0
    held, failure = lines(out)
    assert held["event"] == "held"
    assert failure["event"] == "frame_failure" and "ValueError" in json.dumps(failure)


def test_drain_stops_when_asked_and_keeps_the_rest(out: io.StringIO) -> None:
    q = configure_logging("json", file=out)
    log = structlog.get_logger("t")
    q.active = True
    for i in range(5):
        log.info("n", i=i)
    asked = []

    def stop() -> bool:
        asked.append(1)
        return len(asked) > 2  # a frame waits before the third line

    assert q.drain(stop) == 2
    assert [x["i"] for x in lines(out)] == [0, 1]
    assert len(q) == 3
    assert q.drain() == 3
    assert [x["i"] for x in lines(out)] == [0, 1, 2, 3, 4]


def test_a_full_queue_writes_everything_rather_than_grow(out: io.StringIO) -> None:
    q = configure_logging("json", file=out)
    q.limit = 3
    log = structlog.get_logger("t")
    q.active = True
    for i in range(3):
        log.info("n", i=i)
    assert out.getvalue() == ""
    log.info("n", i=3)
    assert [x["i"] for x in lines(out)] == [0, 1, 2, 3]
    assert len(q) == 0


def test_lines_below_the_level_are_dropped_not_held(out: io.StringIO) -> None:
    q = configure_logging("json", logging.INFO, file=out)
    q.active = True
    structlog.get_logger("t").debug("noise")
    assert len(q) == 0
    q.active = False
    structlog.get_logger("t").debug("noise")
    assert out.getvalue() == ""


def test_a_queue_on_its_own_drains_nothing() -> None:
    assert LogQueue().drain() == 0


def test_the_schedule_writes_held_lines_once_the_firmware_is_done(out: io.StringIO) -> None:
    """The AL transitions the firmware logs after a reply are held, and written when the
    work after the reply ends, not while a frame waits (decisions P19, P37)."""
    q = configure_logging("json", file=out)
    m, _, _ = op_segment(2)
    sched = m.seg.schedule
    now = m.clock.now_ns() if m.clock is not None else 0
    q.active = True
    sched.held_logs, sched.write_logs = q.held, q.drain
    waiting = [True]
    sched.frame_waiting = lambda: waiting[0]
    sched.probe_ns = 0  # look after every slave
    out.truncate(0)
    out.seek(0)
    r = m.one(dg.build(dg.Cmd.BWR, 0, 0x0120, b"\x02\x00"), service=False)  # OP -> PREOP
    assert r.wkc == 2
    sched.service_at(now)  # slave 0's firmware, then the frame waits
    assert out.getvalue() == ""
    assert len(q) == 1
    waiting[0] = False
    sched.service_at(now)
    assert len(q) == 0
    changes = [(x["slave"], x["state"]) for x in lines(out) if x["event"] == "al_state"]
    assert changes == [(0, "PREOP"), (1, "PREOP")]
