"""The CPU follower (decision K5): probe sockets count the EtherCAT frames that arrive by the
CPU they arrive on, and poll() pins the caller to the CPU most came from. A veth pair in two
namespaces; this process sends from one CPU, then another (pinning itself to send, so its
CPU set is checked right after a move only), and each send returns once a tap on the
slave's interface has seen the frame: the receive path (and with it the probes' count) has
run on the sending CPU by then, however late a busy host gets to it. Root."""

from __future__ import annotations

import os
import select
import socket
import time
from collections.abc import Iterator

import pytest

from ecatsim.link import follow
from ecatsim.link.follow import CpuFollower
from tests.integration.netns import NetnsPair, in_netns, require_root

ECAT = b"\xff" * 6 + b"\x02" * 6 + b"\x88\xa4" + bytes(46)
TAGGED = b"\xff" * 6 + b"\x02" * 6 + b"\x81\x00\x00\x05\x88\xa4" + bytes(42)
IPV4 = b"\xff" * 6 + b"\x02" * 6 + b"\x08\x00" + bytes(46)
#: every protocol, for the tap that sees frames pass (linux/if_ether.h)
ETH_P_ALL = 0x0003


def two_cpus() -> tuple[int, int]:
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        pytest.fail(f"the follower tests need two CPUs (this process may use {cpus})")
    return cpus[0], cpus[1]


#: the source address of every frame these tests send
SRC = ECAT[6:12]
#: how long a frame may take to pass the slave's interface on a busy host
SEEN_S = 5.0


class Sender:
    """A packet socket whose send() returns once ``witness`` (a tap on the slave's
    interface, which sees frames in both directions) has seen the frame."""

    def __init__(self, sock: socket.socket, witness: socket.socket) -> None:
        self.sock = sock
        self.witness = witness

    def send(self, frame: bytes) -> None:
        self.sock.send(frame)
        end = time.monotonic() + SEEN_S
        while (left := end - time.monotonic()) > 0:
            ready = select.select([self.witness], [], [], left)[0]
            if ready and self.witness.recv(2048)[6:12] == SRC:
                return
        pytest.fail(f"a frame sent was not seen on the slave's interface in {SEEN_S} s")


@pytest.fixture
def rig() -> Iterator[tuple[CpuFollower, Sender, Sender]]:
    """(follower on the slave end, a sender on the master end, a sender on the slave end);
    this process's CPU set is restored afterwards."""
    require_root("the CPU follower test")
    allowed = os.sched_getaffinity(0)
    with NetnsPair() as pair:
        with in_netns(pair.slave_ns):
            f = CpuFollower(pair.slave_if)
            own = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
            own.bind((pair.slave_if, 0))
            witness = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
            witness.bind((pair.slave_if, ETH_P_ALL))
        with in_netns(pair.master_ns):
            master = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
            master.bind((pair.master_if, 0))
        try:
            yield f, Sender(master, witness), Sender(own, witness)
        finally:
            os.sched_setaffinity(0, allowed)
            master.close()
            own.close()
            witness.close()
            f.close()


def send_from(cpu: int, sock: Sender, *frames: bytes) -> None:
    os.sched_setaffinity(0, {cpu})
    for frame in frames:
        sock.send(frame)


def test_probes_count_ethercat_frames_by_the_cpu_they_arrive_on(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    f, master, own = rig
    a, b = two_cpus()
    for cpu in (a, b, a):
        send_from(cpu, master, ECAT, ECAT, ECAT, TAGGED, IPV4)
        send_from(cpu, own, ECAT)  # the daemon's own replies leave, they do not arrive
        want = [0] * f.ncpu
        want[cpu] = 4
        assert f.counts() == want
    assert f.counts() == [0] * f.ncpu  # drained


def test_poll_pins_to_the_cpu_most_frames_came_from(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    f, master, _ = rig
    a, b = two_cpus()
    t = 1_000_000_000
    assert f.poll(t) is None and f.cpu is None  # nothing came yet
    send_from(b, master, ECAT, ECAT)
    send_from(a, master, ECAT)
    assert f.poll(t) == b and f.cpu == b and f.moves == 1
    assert os.sched_getaffinity(0) == {b}
    assert f.poll(t) is None  # nothing new
    send_from(b, master, ECAT, ECAT)
    assert f.poll(t) is None and f.cpu == b  # frames on its own CPU: it stays
    send_from(b, master, ECAT, ECAT, ECAT)
    send_from(a, master, ECAT)
    # its own CPU's frames do not hold it back: they were read late (the look comes with
    # the first frame from elsewhere), so the other CPU's are the newer
    assert f.poll(t) == a and f.moves == 2 and os.sched_getaffinity(0) == {a}
    f.due_ns = t + follow.BACKOFF_NS  # as after a failed move
    send_from(b, master, ECAT)
    assert f.poll(t) is None and f.cpu == a and f.moves == 2


def readable(f: CpuFollower) -> bool:
    return bool(select.select([f], [], [], 0)[0])


def test_its_descriptor_is_readable_when_frames_come_in_on_another_cpu(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    """The daemon's wait watches fileno(): frames on the CPU it is pinned to leave it quiet
    (nothing runs per frame), a frame on another CPU makes it readable until poll()."""
    f, master, _ = rig
    a, b = two_cpus()
    t = 1_000_000_000
    assert not readable(f)
    send_from(b, master, ECAT)
    assert readable(f)  # not pinned yet: any CPU
    assert f.poll(t) == b and not readable(f)
    send_from(b, master, ECAT, ECAT, ECAT)
    assert not readable(f)
    send_from(a, master, ECAT)
    assert readable(f)
    assert f.poll(t) == a and not readable(f)
    send_from(a, master, ECAT)
    assert not readable(f)
    assert f.counts()[a] == 1  # its own CPU's probe still counts, for the next look


def test_a_cpu_the_daemon_may_not_use_is_not_followed(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    f, master, _ = rig
    a, b = two_cpus()
    f.allowed = {a}  # as a cpuset that leaves the daemon one CPU would
    send_from(b, master, ECAT, ECAT)
    assert f.poll(1) is None and f.cpu is None


def test_a_master_that_keeps_moving_away_pauses_the_following(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    """More than CHASE_MOVES moves within a second: the daemon stops following for
    CHASE_PAUSE_NS and may run on all its CPUs again."""
    f, master, _ = rig
    a, b = two_cpus()
    allowed = f.allowed
    t = 5_000_000_000
    for k in range(follow.CHASE_MOVES):
        cpu = (a, b)[k % 2]
        send_from(cpu, master, ECAT)
        assert f.poll(t + k) == cpu
    send_from(a if f.cpu == b else b, master, ECAT)
    assert f.poll(t + follow.CHASE_MOVES) is None
    due = t + follow.CHASE_MOVES + follow.CHASE_PAUSE_NS
    assert (f.pauses, f.cpu, f.due_ns, f.look_ns) == (1, None, due, due)
    assert os.sched_getaffinity(0) == allowed
    send_from(a, master, ECAT)
    assert not readable(f)  # paused: nothing is watched, the daemon looks at look_ns
    assert f.poll(t + follow.CHASE_PAUSE_NS) is None  # still paused
    send_from(b, master, ECAT)
    assert f.poll(due) == b and f.look_ns == 0  # following again
    send_from(a, master, ECAT)
    assert readable(f)


def test_a_daemon_busier_than_half_a_cpu_does_not_follow(
    rig: tuple[CpuFollower, Sender, Sender],
) -> None:
    """On the master's CPU a daemon with a large segment's SYNC0 work would leave the
    master too little of it: busier than BUSY_SHARE since its last look, it pauses the
    following as after a chase and may run on all its CPUs."""
    f, master, _ = rig
    a, b = two_cpus()
    used = [0]
    f.cpu_time = lambda: used[0]
    t = 7_000_000_000
    send_from(b, master, ECAT)
    assert f.poll(t) == b  # the window starts: nothing measured yet
    used[0] += 40_000_000  # 40 % of the next 100 ms
    send_from(a, master, ECAT)
    assert f.poll(t + follow.BUSY_WINDOW_NS) == a and f.busy_pauses == 0
    used[0] += 60_000_000  # 60 % of the next 100 ms
    send_from(b, master, ECAT)
    now = t + 2 * follow.BUSY_WINDOW_NS
    assert f.poll(now) is None
    due = now + follow.CHASE_PAUSE_NS
    assert (f.busy_pauses, f.pauses, f.cpu, f.look_ns) == (1, 1, None, due)
    assert os.sched_getaffinity(0) == f.allowed
