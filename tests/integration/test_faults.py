"""Injected faults over the control socket, observed by pysoem the standard way.
Ref: issue "reliability" (AL and mailbox faults)."""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pysoem
import pytest

from ecatsim.ctl.server import request
from tests.integration.netns import in_netns
from tests.integration.test_esc_master import to_op

pytestmark = pytest.mark.integration


def ctl_slave(daemon_factory: Any, master_factory: Any, tmp_path: Path) -> tuple[Path, Any, Any]:
    """One drive behind a control socket, found by a master (PREOP): (socket, master,
    slave); SDO reads wait up to 200 ms."""
    sock = tmp_path / "ctl.sock"
    daemon_factory("--ctl", str(sock))
    m = master_factory()
    m.sdo_read_timeout = 200_000
    assert m.config_init() == 1
    return sock, m, m.slaves[0]


def op_with_ctl(
    daemon_factory: Any, master_factory: Any, tmp_path: Path, n: int
) -> tuple[Path, Any, Callable[[], int]]:
    """n drives in OP behind a control socket; cycle() returns the WKC (-1: no reply)."""
    sock = tmp_path / "ctl.sock"
    daemon_factory("--ctl", str(sock), "--slaves", str(n))
    m = master_factory()
    assert m.config_init() == n
    to_op(m)

    def cycle() -> int:
        m.send_processdata()
        return int(m.receive_processdata(20_000))

    return sock, m, cycle


def test_al_refuse_and_fall(daemon_factory: Any, master_factory: Any, tmp_path: Path) -> None:
    sock, m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    assert request(sock, {"cmd": "al_refuse", "slave": 0, "code": 0x0017})["ok"]
    m.config_map()
    assert m.state_check(pysoem.SAFEOP_STATE, 300_000) != pysoem.SAFEOP_STATE
    m.read_state()
    assert s.state == pysoem.PREOP_STATE | pysoem.STATE_ERROR
    assert s.al_status == 0x0017
    # the fault is used up: acknowledge and go on to OP
    s.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK
    s.write_state()
    assert s.state_check(pysoem.SAFEOP_STATE, 1_000_000) == pysoem.SAFEOP_STATE
    to_op(m)
    assert request(sock, {"cmd": "al_fall", "slave": 0, "code": 0x001A})["ok"]
    m.read_state()
    assert s.state == pysoem.SAFEOP_STATE | pysoem.STATE_ERROR
    assert s.al_status == 0x001A
    status = request(sock, {"cmd": "status"})
    assert (
        status["slaves"][0]["al_status"] == 0x14 and status["slaves"][0]["al_status_code"] == 0x1A
    )


def test_mailbox_no_reply_then_recovers(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, _m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    assert request(sock, {"cmd": "mbx_drop", "slave": 0, "count": 1})["ok"]
    with pytest.raises((pysoem.WkcError, pysoem.SdoError, pysoem.MailboxError)):
        s.sdo_read(0x1000, 0)  # no reply: the master times out
    assert struct.unpack("<I", s.sdo_read(0x1000, 0))[0] == 0xFFFC0192


def test_wire_faults_seen_as_wkc_mismatch_and_lost_frames(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 2)
    expected = m.expected_wkc

    assert cycle() == expected
    assert request(sock, {"cmd": "wire", "kind": "wkc", "count": 2, "value": -1})["ok"]
    assert [cycle() for _ in range(3)] == [expected - 1, expected - 1, expected]
    assert request(sock, {"cmd": "wire", "kind": "drop", "count": 1})["ok"]
    assert cycle() < 0  # the reply never came
    assert cycle() == expected  # recovered
    assert request(sock, {"cmd": "wire", "kind": "duplicate", "count": 1})["ok"]
    assert cycle() == expected  # the master takes one copy ...
    assert cycle() == expected  # ... and is not confused by the other


def test_link_down_seen_in_dl_status_lost_link_and_wkc(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 3)
    expected = m.expected_wkc

    assert cycle() == expected
    assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": False})["ok"]
    assert cycle() == expected - 3  # the third drive is cut off
    s1 = m.slaves[1]
    assert s1._fprd(0x0110, 2) == bytes([0x13, 0x56])  # port 1: no link, loop closed
    assert s1._fprd(0x0311, 1) == b"\x01"  # lost link counter, port 1
    assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": True})["ok"]
    assert cycle() == expected  # the segment recovers when the fault is cleared
    assert s1._fprd(0x0110, 2) == bytes([0x33, 0x5A])


def inject(sock: Path, **fault: object) -> int:
    reply = request(sock, {"cmd": "inject", "fault": fault})
    assert reply["ok"], reply
    return int(reply["id"])


def test_delay_and_corrupt_seen_as_late_frame_and_bad_inputs(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 1)
    expected = m.expected_wkc
    s = m.slaves[0]
    assert cycle() == expected
    good = bytes(s.input)
    # 250 ms: far past the master's 20 ms timeout, even if the master itself stalls for a
    # while between send and receive (SOEM's timeout starts at the receive call)
    inject(sock, kind="delay", value=250_000)
    assert cycle() < 0  # the reply is late: lost for this cycle
    assert [cycle() for _ in range(3)] == [expected] * 3  # the next frames are on time
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.3:  # the late reply arrives meanwhile: the master
        assert cycle() == expected  # ignores its stale index
        time.sleep(0.002)
    # the corrupted byte is the middle of the LRW: outputs (12) then inputs, byte 14 = input 2
    inject(sock, kind="corrupt")
    assert cycle() == expected
    assert bytes(s.input) == good[:2] + bytes([good[2] ^ 0xFF]) + good[3:]
    assert cycle() == expected and bytes(s.input) == good


def test_mailbox_faults_seen_by_pysoem(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    inject(sock, kind="sdo_abort", index=0x6060, code=0x08000022)
    with pytest.raises(pysoem.SdoError) as sdo_err:
        s.sdo_read(0x6060, 0)
    assert sdo_err.value.abort_code == 0x08000022
    assert s.sdo_read(0x6060, 0) == b"\x00"  # used up
    inject(sock, kind="mbx_error", code=0x0003)  # MBXERR_INVALIDCHANNEL
    with pytest.raises(pysoem.MailboxError) as mbx_err:
        s.sdo_read(0x1000, 0)
    assert mbx_err.value.error_code == 0x0003
    # SOEM asks for a repeat of the error reply until its timeout (ETG.1000.4 §6.7.4): a
    # real slave repeats it too, so more copies wait on pysoem's error stack
    rest = m._collect_mailbox_errors()
    assert rest and all(isinstance(e, pysoem.MailboxError) and e.error_code == 3 for e in rest)
    # the last repeat may still sit in SM1: SOEM's next request empties it first
    try:
        value = s.sdo_read(0x1000, 0)
    except pysoem.MailboxError as again:
        assert again.error_code == 3
        value = s.sdo_read(0x1000, 0)
    assert struct.unpack("<I", value)[0] == 0xFFFC0192


def test_toggle_error_and_wrong_counter_seen_by_pysoem(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, _m, s = ctl_slave(daemon_factory, master_factory, tmp_path)
    # a 20-byte input mailbox: the 7-byte device name needs a segmented upload
    s.state = pysoem.INIT_STATE
    s.write_state()
    assert s.state_check(pysoem.INIT_STATE, 1_000_000) == pysoem.INIT_STATE
    s.amend_mbx("in", 0x1080, 20)
    s.state = pysoem.PREOP_STATE
    s.write_state()
    assert s.state_check(pysoem.PREOP_STATE, 1_000_000) == pysoem.PREOP_STATE
    assert s.sdo_read(0x1008, 0) == b"TMC8670"
    inject(sock, kind="sdo_toggle")
    with pytest.raises(pysoem.SdoError) as err:
        s.sdo_read(0x1008, 0)
    assert err.value.abort_code == 0x05030000
    assert s.sdo_read(0x1008, 0) == b"TMC8670"
    # wrong counter: raw mailbox traffic through pysoem's FPWR/FPRD
    counters = []
    for c, fault in ((1, False), (2, True), (3, False)):
        if fault:
            inject(sock, kind="mbx_counter")
        req = struct.pack("<HHBBHBHBI", 10, 0, 0, 0x03 | (c << 4), 0x2000, 0x40, 0x1000, 0, 0)
        s._fpwr(0x1000, req.ljust(128, b"\x00"))
        deadline = time.monotonic() + 1.0
        while not s._fprd(0x080D, 1)[0] & 0x08:  # SM1 status: mailbox full
            assert time.monotonic() < deadline, "no mailbox reply"
        reply = s._fprd(0x1080, 20)
        assert reply[8:12] == bytes([0x43, 0x00, 0x10, 0x00])  # the 1000h upload answer
        counters.append(reply[5] >> 4)
    assert counters[1] == counters[0] and counters[2] == counters[0] % 7 + 1


def test_power_cycle_seen_as_init_and_recovered(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 2)
    expected = m.expected_wkc
    assert cycle() == expected
    inject(sock, kind="power_cycle", slave=1, value=200)  # at once
    assert cycle() == expected // 2  # slave 1 is dark
    assert m.slaves[0]._fprd(0x0110, 2)[0] & 0x20 == 0  # slave 0: no link on port 1
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.25:  # keep cycling: slave 0's watchdog stays fed
        assert cycle() == expected // 2
        time.sleep(0.002)
    assert cycle() == expected // 2  # powered up again, but in INIT: no process data
    with pytest.raises(pysoem.WkcError):
        m.slaves[1]._fprd(0x0010, 2)  # its station address is back to the reset value 0
    assert m.slaves[0]._fprd(0x0130, 2) == b"\x08\x00"  # slave 0 is still in OP
    assert m.config_init() == 2  # a master re-scans and brings it back
    to_op(m)
    assert cycle() == m.expected_wkc == expected


def test_time_window_and_seeded_probability(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 1)
    expected = m.expected_wkc
    inject(sock, kind="wkc", value=-1, after_s=0.3, for_s=0.3)
    t0 = time.monotonic()
    seen: list[tuple[float, float, int]] = []  # (sent after, answered before, wkc)
    while (t := time.monotonic() - t0) < 0.9:
        w = cycle()
        seen.append((t, time.monotonic() - t0, w))
        time.sleep(0.002)
    assert all(w == expected for a, b, w in seen if b < 0.25)
    assert all(w == expected - 1 for a, b, w in seen if a > 0.35 and b < 0.55)
    assert all(w == expected for a, b, w in seen if a > 0.65)
    assert sum(1 for a, b, w in seen if a > 0.35 and b < 0.55) > 20  # the window was seen

    def pattern() -> list[int]:
        fid = inject(sock, kind="drop", probability=0.25, seed=11)
        out = [cycle() for _ in range(120)]
        request(sock, {"cmd": "clear", "id": fid})
        return out

    a = pattern()
    assert a == pattern()  # the same seed, the same lost frames
    assert 10 <= a.count(-1) <= 55 and set(a) == {-1, expected}


def test_faults_from_the_segment_yaml(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    seg = tmp_path / "segment.yaml"
    seg.write_text(
        "slaves: [{device: tmc8670}]\n"
        "faults:\n"
        "  - {kind: sdo_abort, index: 0x6061, code: 0x06040047}\n"
        "  - {kind: overtemperature, slave: 0, on_state: op}\n"
    )
    sock = tmp_path / "ctl.sock"
    daemon_factory("--ctl", str(sock), "--config", str(seg))
    m = master_factory()
    assert m.config_init() == 1
    s = m.slaves[0]
    with pytest.raises(pysoem.SdoError) as err:
        s.sdo_read(0x6061, 0)
    assert err.value.abort_code == 0x06040047
    to_op(m)
    for _ in range(20):
        m.send_processdata()
        m.receive_processdata(20_000)
    emcys: list[Any] = []
    s.add_emergency_callback(emcys.append)
    assert struct.unpack("<H", s.sdo_read(0x603F, 0))[0] == 0x4310  # overtemperature
    assert [e.error_code for e in emcys] == [0x4310]
    status = request(sock, {"cmd": "status"})
    assert [f["kind"] for f in status["faults"]] == ["overtemperature"]
    assert request(sock, {"cmd": "clear"})["cleared"] == 1


def test_link_down_after_n_frames_and_circulating_bit(
    daemon_factory: Any, master_factory: Any, tmp_path: Path, netns_pair: Any
) -> None:
    sock, m, cycle = op_with_ctl(daemon_factory, master_factory, tmp_path, 2)
    expected = m.expected_wkc
    fid = inject(sock, kind="link_down", slave=0, port=1, after_frames=5)
    assert [cycle() for _ in range(7)] == [expected] * 5 + [expected // 2] * 2
    assert m.slaves[0]._fprd(0x0311, 1) == b"\x01"  # lost link counter, port 1
    request(sock, {"cmd": "clear", "id": fid})
    assert cycle() == expected
    # the circulating bit (ETG.1000.4 §5.4): SOEM does not look at it, so read the reply
    # off the wire next to the master
    with in_netns(netns_pair.master_ns):
        raw = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
    raw.bind((netns_pair.master_if, 0))
    raw.settimeout(0.5)
    try:
        inject(sock, kind="circulating")
        flags = []
        for _ in range(2):
            assert cycle() == expected
            while True:
                data, addr = raw.recvfrom(2048)
                if addr[2] != 4:  # not our own outgoing frame: the reply
                    break
            flags.append(struct.unpack_from("<H", data, 14 + 2 + 6)[0] & 0x4000)
        assert flags == [0x4000, 0]
    finally:
        raw.close()
