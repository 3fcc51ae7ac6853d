"""A segment beyond one process, seen by pysoem: two daemons chained over a veth (the
first one's --out-iface is the second one's --iface), cable redundancy (the daemon's
--out-iface is the master's second NIC, SOEM's redundant mode) and a junction.

Ref: TMC8460 §5.17 (loop control), §5.19 (DL status), §5.50 (DC receive times, system
time delay); ETG.1000.4 §5.4; SOEM ecx_init_redundant / ecx_waitinframe_red.
"""

from __future__ import annotations

import struct
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pysoem
import pytest

from ecatsim.ctl.server import request
from tests.integration.netns import Daemon, ExtraNetns, NetnsPair, Port, add_veth, in_netns
from tests.integration.test_esc_master import PRODUCT, REVISION, VENDOR, to_op

pytestmark = pytest.mark.integration

RX_US = 20_000
CYCLE_S = 0.001


def _yaml(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _serials(m: Any) -> list[int]:
    """SII serial numbers (words 0x0E/0x0F) in auto-increment order."""
    return [struct.unpack("<I", s.eeprom_read(0x0E))[0] for s in m.slaves]


def _cycles(m: Any, n: int) -> list[int]:
    """n process-data cycles at 1 ms: the WKC of each."""
    out = []
    t = time.monotonic()
    for _ in range(n):
        m.send_processdata()
        out.append(int(m.receive_processdata(RX_US)))
        t += CYCLE_S
        time.sleep(max(0.0, t - time.monotonic()))
    return out


def _all_op(m: Any) -> bool:
    m.read_state()
    return all(s.state == pysoem.OP_STATE for s in m.slaves)


@pytest.fixture
def stop_daemons() -> Iterator[list[Daemon]]:
    daemons: list[Daemon] = []
    yield daemons
    for d in daemons:
        d.stop()


def test_two_daemons_chained_are_one_segment(
    netns_pair: NetnsPair, master_factory: Any, tmp_path: Path, stop_daemons: list[Daemon]
) -> None:
    with ExtraNetns() as nb:
        b_if, a_out = nb.veth(netns_pair.slave_ns)
        sock_a = tmp_path / "a.sock"
        front = _yaml(tmp_path / "a.yaml", "slaves: [{device: tmc8670, count: 2, serial: 1}]\n")
        back = _yaml(tmp_path / "b.yaml", "slaves: [{device: tmc8670, count: 3, serial: 11}]\n")
        db = Daemon(Port(nb.ns, b_if), ["--config", str(back), "--ctl", str(tmp_path / "b.sock")],
                    tmp_path / "b.log")  # fmt: skip
        da = Daemon(
            netns_pair,
            ["--config", str(front), "--out-iface", a_out, "--ctl", str(sock_a)],
            tmp_path / "a.log",
        )
        stop_daemons += [db, da]
        db.start()
        da.start()
        m = master_factory()
        assert m.config_init() == 5
        assert [(s.man, s.id, s.rev) for s in m.slaves] == [(VENDOR, PRODUCT, REVISION)] * 5
        assert _serials(m) == [1, 2, 11, 12, 13]
        m.config_dc()
        # the propagation delays SOEM computed (0x0928): they grow along the chain, the
        # step into the second daemon (a veth and another process) the largest
        delays = [struct.unpack("<I", s._fprd(0x0928, 4))[0] for s in m.slaves]
        assert delays[0] == 0
        assert delays == sorted(delays) and len(set(delays)) == 5, delays
        assert delays[2] - delays[1] > delays[1] - delays[0], delays
        to_op(m)
        wkcs = _cycles(m, 1000)
        assert wkcs == [m.expected_wkc] * 1000
        assert _all_op(m)
        # SOEM's FRMW of the system time ran every cycle: each slave's time loop (0x092C,
        # bit 31 the sign) holds its copy near the reference's, across daemons (the best
        # of five looks: one frame late on a loaded host shows as one large difference)
        looks = []
        for _ in range(5):
            _cycles(m, 5)
            looks.append(
                [struct.unpack("<I", s._fprd(0x092C, 4))[0] & 0x7FFFFFFF for s in m.slaves]
            )
        best = [min(col) for col in zip(*looks, strict=True)]
        assert max(best) < 50_000, looks
        status = request(sock_a, {"cmd": "status"})
        assert status["topology"] == ["master - 0 - 1 - out"]
        # a break at the boundary: the master's next scan finds the front half
        assert request(sock_a, {"cmd": "link", "slave": 1, "port": 1, "up": False})["ok"]
        assert m.config_init() == 2
        assert _serials(m) == [1, 2]
        lost = m.slaves[1]._fprd(0x0311, 1)
        assert lost == b"\x01"


def test_redundancy_ring_survives_a_break(
    netns_pair: NetnsPair, tmp_path: Path, stop_daemons: list[Daemon]
) -> None:
    """Master NIC0 -> 4 slaves -> master NIC1, SOEM's redundant mode (pysoem's
    ``open(ifname, ifname_red)`` is ``ecx_init_redundant``)."""
    red_m, red_s = add_veth(netns_pair.master_ns, netns_pair.slave_ns)
    sock = tmp_path / "ctl.sock"
    d = Daemon(netns_pair, ["--slaves", "4", "--out-iface", red_s, "--ctl", str(sock)],
               tmp_path / "d.log")  # fmt: skip
    stop_daemons.append(d)
    d.start()
    m = pysoem.Master()
    with in_netns(netns_pair.master_ns):
        m.open(netns_pair.master_if, red_m)
    try:
        time.sleep(0.2)  # the daemon sees NIC1's carrier (it looks every 50 ms)
        assert m.config_init() == 4
        to_op(m)
        expected = m.expected_wkc
        assert _cycles(m, 500) == [expected] * 500
        assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": False})["ok"]
        broken = _cycles(m, 500)
        assert broken == [expected] * 500
        assert _all_op(m)
        st = request(sock, {"cmd": "status"})
        assert [s["lost_link"] for s in st["slaves"]][1:3] == [[0, 1], [1, 0]]
        assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": True})["ok"]
        assert _cycles(m, 500) == [expected] * 500
        assert _all_op(m)
    finally:
        m.close()


JUNCTION = """\
slaves:
  - device: tmc8670          # the junction: ports 0-3 (like an EK1122 coupler)
    serial: 1
    port3: [{device: tmc8670, count: 2, serial: 21}]
    port2: [{device: tmc8670, serial: 31}]
  - {device: tmc8670, serial: 2}
"""


def test_junction_reaches_op_with_positions_in_processing_order(
    daemon_factory: Any, master_factory: Any, tmp_path: Path
) -> None:
    sock = tmp_path / "ctl.sock"
    cfg = _yaml(tmp_path / "j.yaml", JUNCTION)
    daemon_factory("--config", str(cfg), "--ctl", str(sock))
    m = master_factory()
    assert m.config_init() == 5
    # processing order 0 -> 3 -> 1 -> 2: junction, port-3 line, main line, port-2 line
    assert _serials(m) == [1, 21, 22, 2, 31]
    dl = struct.unpack("<H", m.slaves[0]._fprd(0x0110, 2))[0]
    assert dl & 0xF0 == 0xF0 and dl >> 8 == 0xAA  # four links, all open and talking
    m.config_dc()
    to_op(m)
    assert _cycles(m, 200) == [m.expected_wkc] * 200
    assert _all_op(m)
    status = request(sock, {"cmd": "status"})
    assert status["topology"] == ["master - 0 - 3", "0.port3 - 1 - 2", "0.port2 - 4"]


def test_redundancy_ring_with_a_soem_c_master(
    netns_pair: NetnsPair, tmp_path: Path, stop_daemons: list[Daemon]
) -> None:
    """The same ring under a C master against SOEM built from pysoem's source
    distribution (tests/support/red_master.c): ec_init_redundant, OP, 500 cycles whole,
    500 broken between slaves 1 and 2, 500 healed; every slave in OP throughout. A test of
    function, not of time: the master waits 50 ms for a frame (decision K11), so every
    cycle of every phase must come back whole."""
    from tests.support.soem_build import red_master

    exe = red_master()
    red_m, red_s = add_veth(netns_pair.master_ns, netns_pair.slave_ns)
    sock = tmp_path / "ctl.sock"
    d = Daemon(netns_pair, ["--slaves", "4", "--out-iface", red_s, "--ctl", str(sock)],
               tmp_path / "d.log")  # fmt: skip
    stop_daemons.append(d)
    d.start()
    time.sleep(0.2)  # the daemon sees NIC1's carrier
    cmd = ["ip", "netns", "exec", netns_pair.master_ns, str(exe), netns_pair.master_if, red_m]
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdin is not None and proc.stdout is not None

    def ask(line: str) -> str:
        assert proc.stdin is not None and proc.stdout is not None
        proc.stdin.write(line + "\n")
        proc.stdin.flush()
        return proc.stdout.readline().strip()

    def cycles_whole() -> None:
        """500 cycles: every reply back, with the full WKC, and every slave in OP after."""
        assert ask("cycles 500").split() == ["cycles", "500", "bad", "0", "late", "0", "op", "1"]

    try:
        ready = proc.stdout.readline().split()
        assert ready[:2] == ["ready", "4"], ready
        cycles_whole()
        assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": False})["ok"]
        cycles_whole()
        dl = [s["dl_status"] for s in request(sock, {"cmd": "status"})["slaves"]]
        assert (dl[1] >> 5 & 1, dl[2] >> 4 & 1) == (0, 0)  # the break: no link either end
        assert request(sock, {"cmd": "link", "slave": 1, "port": 1, "up": True})["ok"]
        cycles_whole()
        proc.stdin.write("quit\n")
        proc.stdin.flush()
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
