"""Injected faults over the control socket, observed by pysoem the standard way.
Ref: issue "reliability" (AL and mailbox faults)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pysoem
import pytest

from ecatsim.ctl import request
from tests.integration.test_esc_master import to_op

pytestmark = pytest.mark.integration


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
    sock = tmp_path / "ctl.sock"
    daemon_factory("--ctl", str(sock))
    m = master_factory()
    assert m.config_init() == 1
    s = m.slaves[0]
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
    sock = tmp_path / "ctl.sock"
    daemon_factory("--ctl", str(sock))
    m = master_factory()
    m.sdo_read_timeout = 200_000
    assert m.config_init() == 1
    s = m.slaves[0]
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
