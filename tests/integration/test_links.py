"""The daemon on each link kind: raw socket (with and without VLAN tag), TAP and UDP.

Ref: ETG.1000.4 §5.3 (EtherType 0x88A4, UDP port 0x88A4), IEEE 802.1Q.
"""

from __future__ import annotations

import select
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ecatsim.wire import datagram as dg
from tests.integration.netns import NetnsPair, in_netns

pytestmark = pytest.mark.integration

BRD_TYPE = dg.build(dg.Cmd.BRD, 0, 0x0000, b"\x00\x00")
SRC = b"\x02\x00\x00\x00\x00\x07"


def _recv_reply(sock: socket.socket, want: bytes, timeout: float = 2.0) -> bytes:
    """The first received frame whose payload after the MACs starts with ``want``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r, _, _ = select.select([sock], [], [], 0.1)
        if not r:
            continue
        data = sock.recv(2048)
        if data[12 : 12 + len(want)] == want and data[6] & 0x02:
            return data
    raise AssertionError("no reply")


@pytest.fixture
def raw_master(netns_pair: NetnsPair) -> Iterator[socket.socket]:
    with in_netns(netns_pair.master_ns):
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
        s.bind((netns_pair.master_if, 0))
    yield s
    s.close()


def test_raw_link_untagged(daemon_factory: Any, raw_master: socket.socket) -> None:
    daemon_factory("--slaves", "2")
    raw_master.send(dg.ethernet_frame([BRD_TYPE], src=SRC))
    reply = _recv_reply(raw_master, b"\x88\xa4")
    assert reply[6:12] == bytes([SRC[0] | 0x02]) + SRC[1:]  # source MAC bit 1 set
    r = dg.HEADER.unpack_from(reply, 16)
    assert r[2] == 2  # ADP incremented by both slaves
    assert reply[16 + 10 : 16 + 12] == b"\xd0\x60"
    assert struct.unpack_from("<H", reply, 16 + 12)[0] == 2  # WKC


def test_raw_link_vlan_tagged(daemon_factory: Any, raw_master: socket.socket) -> None:
    daemon_factory("--slaves", "3")
    # the receiving kernel moves the tag into packet metadata: ask for it back
    raw_master.setsockopt(263, 8, 1)  # SOL_PACKET, PACKET_AUXDATA
    raw_master.send(dg.ethernet_frame([BRD_TYPE], src=SRC, vlan=0x2064))
    deadline = time.monotonic() + 2
    while time.monotonic() < deadline:
        r, _, _ = select.select([raw_master], [], [], 0.1)
        if not r:
            continue
        data, anc, _f, _a = raw_master.recvmsg(2048, 64)
        if data[12:14] != b"\x88\xa4" or not data[6] & 0x02:
            continue
        status, _l, _s, _m, _n, tci, _tpid = struct.unpack_from("=IIIHHHH", anc[0][2])
        assert status & 0x10 and tci == 0x2064  # the reply carries the same VLAN tag
        assert data[16 + 10 : 16 + 12] == b"\xd0\x60"
        assert struct.unpack_from("<H", data, 16 + 12)[0] == 3
        return
    raise AssertionError("no reply")


def test_raw_link_ignores_other_ethertypes(daemon_factory: Any, raw_master: socket.socket) -> None:
    daemon = daemon_factory()
    raw_master.send(b"\xff" * 6 + SRC + b"\x08\x00" + bytes(46))
    raw_master.send(dg.ethernet_frame([BRD_TYPE], src=SRC))
    _recv_reply(raw_master, b"\x88\xa4")
    assert daemon.alive()


def test_tap_link(netns_pair: NetnsPair, tmp_path: Path) -> None:
    name = "tap" + netns_pair.slave_if[2:]
    log = tmp_path / "tap.log"
    cmd = ["ip", "netns", "exec", netns_pair.slave_ns, sys.executable, "-m", "ecatsim", "run",
           "--tap", name, "--slaves", "2"]  # fmt: skip
    with open(log, "wb") as f:
        proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 10
        while "ready" not in log.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log.read_text()
            time.sleep(0.05)
        with in_netns(netns_pair.slave_ns):
            s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
            s.bind((name, 0))
        try:
            s.send(dg.ethernet_frame([BRD_TYPE], src=SRC))
            reply = _recv_reply(s, b"\x88\xa4")
            assert struct.unpack_from("<H", reply, 16 + 12)[0] == 2
        finally:
            s.close()
    finally:
        proc.terminate()
        assert proc.wait(5) == 0, log.read_text()


def test_udp_link(tmp_path: Path) -> None:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    log = tmp_path / "udp.log"
    with open(log, "wb") as f:
        proc = subprocess.Popen(
            [sys.executable, "-m", "ecatsim", "run", "--udp", f"127.0.0.1:{port}"],
            stdout=f,
            stderr=subprocess.STDOUT,
        )
    try:
        deadline = time.monotonic() + 10
        while "ready" not in log.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, log.read_text()
            time.sleep(0.05)
        c = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        c.settimeout(2)
        c.sendto(dg.ecat_frame([BRD_TYPE]), ("127.0.0.1", port))
        data, _ = c.recvfrom(2048)
        c.close()
        assert data[2 + 10 : 2 + 12] == b"\xd0\x60"
        assert struct.unpack_from("<H", data, 2 + 12)[0] == 1
    finally:
        proc.terminate()
        assert proc.wait(5) == 0, log.read_text()
