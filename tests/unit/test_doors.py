"""DoorHost: one epoll descriptor for changing sets of front-door descriptors."""

from __future__ import annotations

import os
import select
from typing import Any

from ecatsim.doors.host import DoorHost, serve_doors


class PipeDoor:
    """A door that owns pipes, echoes what it reads into ``got`` and can fail on demand."""

    def __init__(self) -> None:
        self.pipes: list[tuple[int, int]] = [os.pipe()]
        self.got: list[bytes] = []
        self.now = 0
        self.fail = False

    def fds(self) -> list[int]:
        return [r for r, _ in self.pipes]

    def on_ready(self, fd: int) -> None:
        if self.fail:
            raise RuntimeError("door bug")
        self.got.append(os.read(fd, 100))

    def service(self, now_ns: int) -> None:
        self.now = now_ns

    def deadline_ns(self) -> int | None:
        return 1234

    def status(self) -> dict[str, Any]:
        return {"got": len(self.got)}

    def ctl(self, command: str, args: list[str]) -> dict[str, Any]:
        return {"ok": True}

    def close(self) -> None:
        for r, w in self.pipes:
            os.close(r)
            os.close(w)


def readable(fd: int) -> bool:
    return bool(select.select([fd], (), (), 0)[0])


def test_host_wakes_for_new_and_not_for_closed_descriptors() -> None:
    door = PipeDoor()
    host = DoorHost({"pipe": door})
    assert not readable(host.fileno())
    os.write(door.pipes[0][1], b"a")
    assert readable(host.fileno())
    host.serve()
    assert door.got == [b"a"]
    assert not readable(host.fileno())
    # a descriptor added by the door is watched after the next serve/service
    door.pipes.append(os.pipe())
    host.service(5)
    os.write(door.pipes[1][1], b"b")
    host.serve()
    assert door.got == [b"a", b"b"] and door.now == 5
    # one removed (and closed) is forgotten without error
    r, w = door.pipes.pop(0)
    os.close(r)
    os.close(w)
    host.service(6)
    assert host.next_deadline() == 1234
    assert host.status() == {"pipe": {"got": 2}}
    host.close()


def test_a_descriptor_number_reused_before_the_host_syncs_is_watched() -> None:
    """A door closes a descriptor and gets the same number for a new one between two
    syncs: the host still wakes for the new one."""
    door = PipeDoor()
    host = DoorHost({"pipe": door})
    r, w = door.pipes.pop(0)
    os.close(r)
    os.close(w)
    door.pipes.append(os.pipe())
    assert door.pipes[0][0] == r  # the kernel hands out the lowest free number again
    host.service(1)
    os.write(door.pipes[0][1], b"c")
    assert readable(host.fileno())
    host.serve()
    assert door.got == [b"c"]
    host.close()


def test_a_failing_door_is_counted_and_the_host_goes_on() -> None:
    door = PipeDoor()
    host = DoorHost({"pipe": door})
    door.fail = True
    os.write(door.pipes[0][1], b"x")
    host.serve()
    assert host.failures == 1
    door.fail = False
    host.serve()
    assert door.got == [b"x"]
    host.close()


def test_serve_doors_runs_until_stopped() -> None:
    door = PipeDoor()
    host = DoorHost({"pipe": door})
    wake_r, wake_w = os.pipe()
    seen: list[bytes] = []
    os.write(door.pipes[0][1], b"q")
    os.write(wake_w, b"w")
    serve_doors(
        host,
        now_ns=lambda: 99,
        stop=lambda: bool(seen) and bool(door.got),
        others={wake_r: lambda: seen.append(os.read(wake_r, 10))},
    )
    assert seen == [b"w"] and door.got == [b"q"] and door.now == 99
    os.close(wake_r)
    os.close(wake_w)
    host.close()


def test_the_ethercat_daemon_serves_a_door_between_frames() -> None:
    """A door's descriptor ends the daemon's wait; its deadline is part of the loop's."""
    from ecatsim.ethercat.daemon import Daemon
    from ecatsim.link.loopback import LoopbackLink
    from tests.support.tinymaster import segment_of

    seg, _clock = segment_of(1)
    door = PipeDoor()
    host = DoorHost({"pipe": door})
    d = Daemon(LoopbackLink(), seg, doors=host)
    assert host.fileno() in d._watch
    os.write(door.pipes[0][1], b"z")
    d._serve_others([host.fileno()])
    assert door.got == [b"z"]
    deadline = d._deadline()
    assert deadline is not None and deadline <= 1234
    host.close()
