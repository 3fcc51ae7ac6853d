"""The integration harness itself (no daemon): namespaces, in_netns, pysoem inside a namespace.

Ref: ip-netns(8), setns(2); ETG.1000.4 (EtherType 0x88A4).
"""

from __future__ import annotations

import json
import os
import select
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ecatsim.bench.capture import Capture
from tests.integration.netns import (
    Daemon,
    NetnsPair,
    _is_ready_line,
    in_netns,
    netns_exists,
)

ETH_P_ECAT = 0x88A4


def _netns_inode(ns: str | None = None) -> int:
    if ns is None:
        return os.stat("/proc/thread-self/ns/net").st_ino
    with in_netns(ns):
        return os.stat("/proc/thread-self/ns/net").st_ino


def _links(ns: str) -> str:
    return subprocess.run(
        ["ip", "-n", ns, "-o", "link", "show"], capture_output=True, text=True, check=True
    ).stdout


@pytest.fixture
def slave_sniffer(netns_pair: NetnsPair) -> Iterator[socket.socket]:
    """A raw socket for EtherType 0x88A4 on the slave end, opened inside the slave ns."""
    with in_netns(netns_pair.slave_ns):
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
        s.bind((netns_pair.slave_if, ETH_P_ECAT))
    yield s
    s.close()


def _drain(sock: socket.socket, timeout: float = 1.0) -> list[bytes]:
    frames = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r, _, _ = select.select([sock], [], [], 0.05)
        if r:
            frames.append(sock.recv(2048))
        elif frames:
            break
    return frames


def test_pair_created_and_removed() -> None:
    with NetnsPair() as pair:
        assert netns_exists(pair.master_ns) and netns_exists(pair.slave_ns)
        assert pair.master_if in _links(pair.master_ns)
        assert pair.slave_if in _links(pair.slave_ns)
        assert pair.slave_if not in _links(pair.master_ns)
        for ns, dev in ((pair.master_ns, pair.master_if), (pair.slave_ns, pair.slave_if)):
            assert len(dev) <= 15
            for name in (dev, "lo"):
                info = json.loads(
                    subprocess.run(
                        ["ip", "-n", ns, "-j", "link", "show", "dev", name],
                        capture_output=True,
                        text=True,
                        check=True,
                    ).stdout
                )
                assert "UP" in info[0]["flags"], f"{name} in {ns} is not up"
            # /proc/sys/net follows the calling thread's namespace (/sys would not)
            sysctl = subprocess.run(
                ["ip", "netns", "exec", ns, "sysctl", "-n", f"net.ipv6.conf.{dev}.disable_ipv6"],
                capture_output=True,
                text=True,
                check=False,
            )
            if sysctl.returncode == 0:  # IPv6 may be compiled out
                assert sysctl.stdout.strip() == "1"
    assert not pair.exists()


def test_pair_removed_after_exception() -> None:
    pair = NetnsPair()
    with pytest.raises(RuntimeError, match="boom"), pair:
        assert pair.exists()
        raise RuntimeError("boom")
    assert not pair.exists()


def test_two_concurrent_pairs_have_unique_names() -> None:
    with NetnsPair() as a, NetnsPair() as b:
        names_a = {a.master_ns, a.slave_ns, a.master_if, a.slave_if}
        names_b = {b.master_ns, b.slave_ns, b.master_if, b.slave_if}
        assert len(names_a) == 4 and len(names_b) == 4
        assert not names_a & names_b
        assert a.exists() and b.exists()
    assert not a.exists() and not b.exists()


def test_pairs_created_from_threads_are_unique() -> None:
    pairs: list[NetnsPair] = []
    errors: list[BaseException] = []

    def make() -> None:
        try:
            pair = NetnsPair()
            pairs.append(pair)  # before __enter__: removed below even if creation fails
            pair.__enter__()
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=make) for _ in range(4)]
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert errors == []
        assert len({p.master_ns for p in pairs}) == 4
        assert all(p.exists() for p in pairs)
    finally:
        for p in pairs:
            p.__exit__(None, None, None)
    assert not any(p.exists() for p in pairs)


def test_in_netns_switches_only_this_thread_and_back(netns_pair: NetnsPair) -> None:
    before = _netns_inode()
    inside: dict[str, int] = {}
    entered, checked = threading.Event(), threading.Event()

    def other() -> None:  # started before the switch: stays in the original namespace
        entered.wait(5)
        inside["other"] = _netns_inode()
        checked.set()

    t = threading.Thread(target=other)
    t.start()
    with in_netns(netns_pair.master_ns):
        inside["this"] = _netns_inode()
        entered.set()
        checked.wait(5)
        # a thread started inside the block inherits the namespace (clone(2))
        child = threading.Thread(target=lambda: inside.setdefault("child", _netns_inode()))
        child.start()
        child.join()
        assert socket.if_nametoindex(netns_pair.master_if) > 0
    t.join()
    assert _netns_inode() == before
    assert inside["this"] != before
    assert inside["other"] == before
    assert inside["child"] == inside["this"]
    assert _netns_inode(netns_pair.slave_ns) not in (before, inside["this"])
    with pytest.raises(OSError):
        socket.if_nametoindex(netns_pair.master_if)  # not visible from the original ns


def test_in_netns_restores_after_exception(netns_pair: NetnsPair) -> None:
    before = _netns_inode()
    with pytest.raises(ValueError), in_netns(netns_pair.slave_ns):
        raise ValueError
    assert _netns_inode() == before


def test_in_netns_unknown_namespace() -> None:
    with pytest.raises(RuntimeError, match="does not exist"), in_netns("ecs-no-such-ns"):
        pass


def test_raw_socket_between_namespaces(netns_pair: NetnsPair, slave_sniffer: socket.socket) -> None:
    with in_netns(netns_pair.master_ns):
        m = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
        m.bind((netns_pair.master_if, ETH_P_ECAT))
    try:
        frame = b"\xff" * 6 + b"\x02\x00\x00\x00\x00\x01" + b"\x88\xa4" + bytes(46)
        m.send(frame)
        frames = _drain(slave_sniffer)
        assert frame in frames
    finally:
        m.close()


def test_pysoem_in_master_namespace_reaches_slave_side(
    netns_pair: NetnsPair, slave_sniffer: socket.socket, master_factory: Any
) -> None:
    master = master_factory()
    # No slaves answer: config_init broadcasts (BRD) and finds nobody. SOEM returns the
    # working counter, or EC_NOFRAME (-1) because no frame comes back at all.
    assert master.config_init() in (0, -1)
    frames = _drain(slave_sniffer)
    assert frames, "pysoem sent nothing that reached the slave namespace"
    for f in frames:
        assert f[12:14] == b"\x88\xa4"
    # the first datagram of the first frame is a BRD (command 7)
    assert any(f[16] == 0x07 for f in frames)


def test_ready_line_detection() -> None:
    assert _is_ready_line('{"link": "vs1", "event": "ready", "level": "info"}')
    assert not _is_ready_line('{"event": "not_ready_yet", "msg": "ready"}')
    assert _is_ready_line("2026-01-01T00:00:00Z [info     ] ready     link=vs1")
    assert not _is_ready_line("alreadyfoo")


def test_daemon_that_dies_fails_with_its_log(netns_pair: NetnsPair, tmp_path: Path) -> None:
    d = Daemon(netns_pair, ("--no-such-option-for-the-harness-test",), tmp_path / "d.log")
    with pytest.raises(pytest.fail.Exception, match="exited with"):
        d.start(timeout=20)
    assert not d.alive()
    assert d.stop() is None


def test_a_capture_stops_at_once_on_a_busy_link(netns_pair: NetnsPair) -> None:
    """A capture's thread ends when the block ends, though frames keep arriving (a busy
    link never lets it wait out a select); its sockets are closed only after it ended."""
    frame = bytes.fromhex("ffffffffffff02000000000088a4") + bytes(46)
    stop = threading.Event()

    def flood() -> None:
        with in_netns(netns_pair.master_ns):
            s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW)
        s.bind((netns_pair.master_if, 0))
        while not stop.is_set():
            s.send(frame)
            time.sleep(0.0001)
        s.close()

    sender = threading.Thread(target=flood)
    sender.start()
    try:
        ends = (netns_pair.master_ns, netns_pair.master_if), (netns_pair.slave_ns,
                                                              netns_pair.slave_if)  # fmt: skip
        with Capture.both_ends(*ends) as cap:
            time.sleep(0.3)
            assert cap._thread is not None
            t0 = time.monotonic()
        assert time.monotonic() - t0 < 0.5
        assert not cap._thread.is_alive()
        assert len(cap.raw) > 100  # the flood was seen at the slave's end
    finally:
        stop.set()
        sender.join()
