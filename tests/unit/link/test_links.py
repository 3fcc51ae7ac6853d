"""Links on their own: raw socket over a veth pair, TAP, UDP, loopback, pcap writer.

The raw and TAP tests need root (namespaces, raw sockets): skipped locally without it,
failed in CI. Everything runs inside private namespaces, nothing touches the host's links.
Ref: packet(7), tuntap; ETG.1000.4 (EtherType 0x88A4, UDP port 0x88A4); IEEE 802.1Q.
"""

from __future__ import annotations

import select
import socket
import struct
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from ecatsim.ethercat import daemon
from ecatsim.ethercat.recorder import FrameRecorder
from ecatsim.link.errors import LinkError
from ecatsim.link.loopback import LoopbackLink, Manipulator
from ecatsim.link.pcap import MAGIC_NSEC, MAGIC_USEC, PcapWriter
from ecatsim.link.raw import RawLink, iface_ipv4_addresses
from ecatsim.link.udp import UDP_PORT, UdpLink
from tests.integration.netns import NetnsPair, in_netns, require_root
from tests.support.compiled import require_built

ETH_P_ALL = 0x0003
DST = b"\xff" * 6
SRC = b"\x02\x00\x00\x00\x00\x01"
#: EtherCAT header (length 12, type 1) + one NOP datagram with 2 data bytes
ECAT_PAYLOAD = struct.pack("<H", 12 | 0x1000) + bytes(10) + b"\xaa\xbb" + b"\x00\x00"


def ecat_frame(tag: int = 0, vlan: int | None = None) -> bytes:
    """A 60-byte EtherCAT frame; ``tag`` lands in the datagram data to tell frames apart."""
    body = bytearray(ECAT_PAYLOAD)
    body[12] = tag & 0xFF
    head = DST + SRC
    if vlan is not None:
        head += struct.pack(">HH", 0x8100, vlan)
    frame = head + b"\x88\xa4" + bytes(body)
    return frame + bytes(max(0, 60 - len(frame)))


def wait_recv(link: RawLink | UdpLink, buf: bytearray, timeout: float = 1.0) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        select.select([link.fileno()], [], [], 0.05)
        n = link.recv_into(buf)
        if n:
            return n
    return 0


def sock_recv(sock: socket.socket, timeout: float = 1.0) -> list[bytes]:
    out = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r, _, _ = select.select([sock], [], [], 0.05)
        if r:
            out.append(sock.recv(2048))
        elif out:
            break
    return out


@pytest.fixture
def pair() -> Iterator[NetnsPair]:
    require_root("the raw/TAP link test")
    with NetnsPair() as p:
        yield p


class ResponderLink(RawLink):
    """A RawLink whose receive is the daemon's compiled responder's (``Responder.serve``
    with no segment: wait until the deadline, receive, hand the frame back), so the tests
    below run the compiled receive and the Python reference alike."""

    def __init__(self, iface: str) -> None:
        super().__init__(iface)
        assert daemon.responder is not None
        self._srv = daemon.responder
        self._responder = self._srv.Responder(self.fileno(), (), FrameRecorder())

    def recv_into(self, buf: bytearray) -> int:
        srv = self._srv
        code, n, t_rx = self._responder.serve(buf, time.monotonic_ns())
        if code != srv.FRAME:
            assert code == srv.TIMEOUT, code
            return 0
        self.rx_ns = t_rx
        return int(n)

    def close(self) -> None:
        self._responder.close()
        super().close()


@pytest.fixture(params=[True, False], ids=["responder", "python"])
def raw_pair(
    pair: NetnsPair, request: pytest.FixtureRequest
) -> Iterator[tuple[RawLink, socket.socket, NetnsPair]]:
    """A RawLink on the slave end, receiving as the compiled responder does (decision P4)
    or through Python's socket module; a plain ETH_P_ALL socket on the master end."""
    if request.param:
        require_built(daemon.responder, "ecatsim.ethercat.responder")
    with in_netns(pair.slave_ns):
        link = ResponderLink(pair.slave_if) if request.param else RawLink(pair.slave_if)
    with in_netns(pair.master_ns):
        master = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        master.bind((pair.master_if, 0))
    yield link, master, pair
    master.close()
    link.close()


# --- raw ---------------------------------------------------------------------------------


def test_raw_frames_cross_both_ways(raw_pair: tuple[RawLink, socket.socket, NetnsPair]) -> None:
    link, master, _ = raw_pair
    buf = bytearray(2048)
    for tag in range(3):
        master.send(ecat_frame(tag))
        n = wait_recv(link, buf)
        assert bytes(buf[:n]) == ecat_frame(tag)
    reply = bytearray(ecat_frame(7))
    reply[6] |= 0x02
    link.send(memoryview(reply))
    got = [f for f in sock_recv(master) if f[12:14] == b"\x88\xa4"]
    assert got == [bytes(reply)]


def test_raw_ignores_own_outgoing_frames(
    raw_pair: tuple[RawLink, socket.socket, NetnsPair],
) -> None:
    link, master, _ = raw_pair
    buf = bytearray(2048)
    for tag in range(5):
        link.send(memoryview(ecat_frame(tag)))
    assert len([f for f in sock_recv(master) if f[12:14] == b"\x88\xa4"]) == 5
    time.sleep(0.05)
    assert link.recv_into(buf) == 0
    # Frames another socket on this host sends out of the same interface are
    # PACKET_OUTGOING for the link's socket: not requests from the master either.
    _, _, pair = raw_pair
    with in_netns(pair.slave_ns):
        other = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
    try:
        other.bind((pair.slave_if, 0))
        other.send(ecat_frame(11))
        assert ecat_frame(11) in sock_recv(master)
        time.sleep(0.05)
        assert link.recv_into(buf) == 0
    finally:
        other.close()


def test_raw_delivers_only_ethercat(raw_pair: tuple[RawLink, socket.socket, NetnsPair]) -> None:
    link, master, _ = raw_pair
    buf = bytearray(2048)
    master.send(DST + SRC + b"\x08\x00" + bytes(46))  # IPv4
    master.send(DST + SRC + b"\x81\x00\x00\x05\x08\x06" + bytes(42))  # tagged ARP
    master.send(DST + SRC + b"\x88\xa5" + bytes(46))  # neighbour of 0x88A4
    master.send(ecat_frame(9))
    n = wait_recv(link, buf)
    assert bytes(buf[:n]) == ecat_frame(9)
    time.sleep(0.05)
    assert link.recv_into(buf) == 0


def test_raw_keeps_vlan_tag(raw_pair: tuple[RawLink, socket.socket, NetnsPair]) -> None:
    link, master, _ = raw_pair
    buf = bytearray(2048)
    frame = ecat_frame(3, vlan=0x2064)
    master.send(frame)
    n = wait_recv(link, buf)
    assert bytes(buf[:n]) == frame  # the tag the kernel moved into metadata is back
    # the receive time stamp is on the monotonic clock, a moment ago
    assert 0 < time.monotonic_ns() - link.rx_ns < 1_000_000_000


def test_raw_brings_interface_up(pair: NetnsPair) -> None:
    subprocess.run(["ip", "-n", pair.slave_ns, "link", "set", pair.slave_if, "down"], check=True)
    with in_netns(pair.slave_ns):
        link = RawLink(pair.slave_if)
    link.close()
    out = subprocess.run(
        ["ip", "-n", pair.slave_ns, "-o", "link", "show", pair.slave_if],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert ",UP" in out or "<UP" in out


def test_iface_ipv4_addresses(pair: NetnsPair) -> None:
    with in_netns(pair.slave_ns):
        assert iface_ipv4_addresses(pair.slave_if) == []
    subprocess.run(
        ["ip", "-n", pair.slave_ns, "addr", "add", "192.0.2.7/24", "dev", pair.slave_if],
        check=True,
    )
    with in_netns(pair.slave_ns):
        assert iface_ipv4_addresses(pair.slave_if) == ["192.0.2.7"]


def test_raw_missing_interface_is_a_link_error() -> None:
    with pytest.raises(LinkError, match="ecsnosuch0") as info:
        RawLink("ecsnosuch0")
    assert "does not exist" in str(info.value) and "--iface" in str(info.value)
    assert isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


# --- TAP ---------------------------------------------------------------------------------


def test_tap_link(pair: NetnsPair) -> None:
    from ecatsim.link.tap import TapLink

    name = "tap" + pair.slave_if[2:]
    with in_netns(pair.slave_ns):
        link = TapLink(name)
        peer = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ALL))
        peer.bind((name, 0))
    try:
        assert link.ethernet
        out = subprocess.run(
            ["ip", "-n", pair.slave_ns, "-o", "link", "show", name],
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        assert "<" in out and "UP" in out.split(">")[0]
        buf = bytearray(2048)
        peer.send(DST + SRC + b"\x08\x00" + bytes(46))  # not EtherCAT: ignored
        peer.send(ecat_frame(5, vlan=0x0007))
        peer.send(ecat_frame(6))
        got: list[bytes] = []
        deadline = time.monotonic() + 1
        while len(got) < 2 and time.monotonic() < deadline:
            select.select([link.fileno()], [], [], 0.05)
            n = link.recv_into(buf)
            if n:
                got.append(bytes(buf[:n]))
        assert got == [ecat_frame(5, vlan=0x0007), ecat_frame(6)]
        link.send(memoryview(ecat_frame(8)))
        assert ecat_frame(8) in sock_recv(peer)
    finally:
        peer.close()
        link.close()


# --- UDP ---------------------------------------------------------------------------------


def test_udp_round_trip() -> None:
    link = UdpLink("127.0.0.1", 0)
    assert UDP_PORT == 34980 and not link.ethernet
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(2)
    try:
        buf = bytearray(2048)
        link.send(memoryview(b"nobody yet"))  # no peer known: silently nothing
        client.sendto(ECAT_PAYLOAD, link.address)
        n = wait_recv(link, buf)
        assert bytes(buf[:n]) == ECAT_PAYLOAD
        assert link.peer == ("127.0.0.1", client.getsockname()[1])
        buf[12] = 0x55
        link.send(memoryview(buf)[:n])
        data, addr = client.recvfrom(2048)
        assert addr == link.address
        assert data == ECAT_PAYLOAD[:12] + b"\x55" + ECAT_PAYLOAD[13:]
    finally:
        client.close()
        link.close()


def test_udp_bind_error_is_a_link_error() -> None:
    first = UdpLink("127.0.0.1", 0)
    try:
        with pytest.raises(LinkError, match=str(first.address[1])):
            UdpLink("127.0.0.1", first.address[1])
    finally:
        first.close()


# --- loopback ----------------------------------------------------------------------------


def test_loopback_round_trip() -> None:
    link = LoopbackLink()
    buf = bytearray(64)
    assert link.recv_into(buf) == 0 and link.master_recv() is None
    link.master_send(ecat_frame(1))
    n = link.recv_into(buf)
    assert n == 60 and bytes(buf[:n]) == ecat_frame(1) and len(buf) == 64
    link.send(memoryview(buf)[:n])
    assert link.master_recv() == ecat_frame(1)
    assert link.fileno() == -1
    link.close()
    link.master_send(ecat_frame(2))
    assert link.recv_into(buf) == 0


def _run_manipulated(seed: int) -> tuple[list[bytes | None], list[int]]:
    m = Manipulator(seed=seed, drop=0.2, duplicate=0.2, corrupt=0.2, delay=0.2, delay_polls=3)
    link = LoopbackLink(to_slave=m)
    buf = bytearray(128)
    seen: list[bytes | None] = []
    for i in range(200):
        link.master_send(ecat_frame(i))
        n = link.recv_into(buf)
        seen.append(bytes(buf[:n]) if n else None)
    s = m.stats
    return seen, [s.seen, s.dropped, s.duplicated, s.corrupted, s.delayed]


def test_manipulator_is_deterministic_per_seed() -> None:
    a, stats_a = _run_manipulated(42)
    b, stats_b = _run_manipulated(42)
    c, _ = _run_manipulated(43)
    assert a == b and stats_a == stats_b
    assert a != c
    assert stats_a[0] == 200 and all(x > 10 for x in stats_a[1:])


def test_manipulator_actions() -> None:
    link = LoopbackLink(to_master=Manipulator(drop=1.0))
    link.send(memoryview(ecat_frame(1)))
    assert link.master_recv() is None

    link.attach(to_master=Manipulator(duplicate=1.0))
    link.send(memoryview(ecat_frame(2)))
    assert [link.master_recv(), link.master_recv(), link.master_recv()] == [
        ecat_frame(2),
        ecat_frame(2),
        None,
    ]

    link.attach(to_master=Manipulator(corrupt=1.0, corrupt_from=14, seed=5))
    link.send(memoryview(ecat_frame(3)))
    got = link.master_recv()
    assert got is not None and got[:14] == ecat_frame(3)[:14]
    diff = [i for i in range(60) if got[i] != ecat_frame(3)[i]]
    assert len(diff) == 1 and diff[0] >= 14

    link.attach(to_master=Manipulator(delay=1.0, delay_polls=2))
    link.send(memoryview(ecat_frame(4)))
    link.attach()
    link.send(memoryview(ecat_frame(5)))  # not delayed: overtakes the delayed one
    assert link.master_recv() == ecat_frame(5)
    assert link.master_recv() is None
    assert link.master_recv() == ecat_frame(4)


def test_manipulator_rejects_bad_probability() -> None:
    with pytest.raises(ValueError, match="drop"):
        Manipulator(drop=1.5)


# --- pcap --------------------------------------------------------------------------------


@pytest.mark.parametrize("nanosecond", [True, False])
def test_pcap_parses_with_scapy(tmp_path: Path, nanosecond: bool) -> None:
    from scapy.layers.l2 import Ether
    from scapy.utils import rdpcap

    path = tmp_path / "frames.pcap"
    ts = 1_700_000_000_123_456_789
    with PcapWriter(path, nanosecond=nanosecond) as w:
        w.write(ecat_frame(1), ts_ns=ts)
        w.write(bytearray(ecat_frame(2, vlan=5)), ts_ns=ts + 1_000_000)
        w.write(memoryview(ecat_frame(3)))
    raw = path.read_bytes()
    assert struct.unpack_from("<I", raw)[0] == (MAGIC_NSEC if nanosecond else MAGIC_USEC)
    pkts = rdpcap(str(path))
    assert [bytes(p) for p in pkts] == [ecat_frame(1), ecat_frame(2, vlan=5), ecat_frame(3)]
    assert isinstance(pkts[0], Ether) and pkts[0].type == 0x88A4
    assert int(pkts[0].time) == 1_700_000_000
    frac = pkts[0].time - 1_700_000_000
    expected = 0.123456789 if nanosecond else 0.123456
    assert abs(float(frac) - expected) < 1e-9


def test_pcap_snaplen_truncates(tmp_path: Path) -> None:
    path = tmp_path / "short.pcap"
    with PcapWriter(path, snaplen=20) as w:
        w.write(ecat_frame(1), ts_ns=0)
    raw = path.read_bytes()
    _sec, _frac, cap, orig = struct.unpack_from("<IIII", raw, 24)
    assert (cap, orig) == (20, 60) and len(raw) == 24 + 16 + 20
