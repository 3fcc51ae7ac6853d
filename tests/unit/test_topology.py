"""Ports are wires: routes through junctions, cable redundancy, an out interface and two
segments chained, in process (the daemon's loop and real masters: tests/integration).

Ref: TMC8460 §5.17 Table 28 (loop control), §5.19 (DL status), §5.38 (lost link
counters), §5.50.1 (receive times); ETG.1000.4 §5.4 (circulating bit).
"""

from __future__ import annotations

import struct
from typing import Any

import pytest
import yaml

from ecatsim.clock import ManualClock
from ecatsim.errors import UserError
from ecatsim.ethercat import topology
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig, parse_segment
from ecatsim.faults.engine import FaultEngine
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import Reply, decode

HOP = 500
TURN = 200


def line(n: int, out: bool = False, clock: ManualClock | None = None) -> Segment:
    clock = clock or ManualClock(1_000_000_000)
    cfg = SegmentConfig(tuple(SlaveConfig(device="echo", serial=i + 1) for i in range(n)))
    seg = build_segment(cfg, clock, out=out)
    if out:
        seg.set_out_link(True)
    return seg


def send(seg: Segment, datagrams: list[bytes], entry: int = 0) -> tuple[list[Reply], int] | None:
    """One frame in at ``entry``: its datagrams as they leave, and where they leave."""
    raw = bytearray(dg.ethernet_frame(datagrams))
    if not seg.process(raw, 14, len(raw), 0, entry):
        return None
    seg.after_reply()
    return decode(bytes(raw), 14), seg.exit


def brd_wkc(seg: Segment, entry: int = 0) -> tuple[int, int]:
    r = send(seg, [dg.build(dg.Cmd.BRD, 0, 0x0000, bytes(1))], entry)
    assert r is not None
    return r[0][0].wkc, r[1]


def number_stations(seg: Segment, n: int) -> None:
    """Station address 0x1000 + k at auto-increment position k (as a master does)."""
    for k in range(n):
        adp = (-k) & 0xFFFF
        r = send(seg, [dg.build(dg.Cmd.APWR, adp, 0x0010, struct.pack("<H", 0x1000 + k))])
        assert r is not None and r[0][0].wkc == 1


def stations(seg: Segment) -> list[int]:
    return [struct.unpack_from("<H", e.mem, 0x0010)[0] for e in seg.escs]


# ----------------------------------------------------------------- a line


def test_line_positions_dl_status_and_receive_times() -> None:
    seg = line(3)
    assert [seg.escs.index(e) for e in seg.chain] == [0, 1, 2]
    assert brd_wkc(seg) == (3, topology.EXIT_MAIN)
    number_stations(seg, 3)
    assert stations(seg) == [0x1000, 0x1001, 0x1002]
    send(seg, [dg.build(dg.Cmd.BWR, 0, 0x0900, bytes(4))])
    t = []
    for e in seg.escs:
        p0, p1 = struct.unpack_from("<II", e.mem, 0x0900)
        t.append((p0, p1))
    # port 1 sees the frame back after the slaves behind (there and back) and the turn
    assert (t[0][1] - t[0][0]) - (t[1][1] - t[1][0]) == 2 * HOP
    assert t[1][1] - t[1][0] == 2 * HOP + TURN
    assert t[2][1] == 0  # the last slave's port 1 sees nothing


def test_forced_open_port_without_link_loses_the_frame() -> None:
    seg = line(2)
    send(seg, [dg.build(dg.Cmd.APWR, 0xFFFF, 0x0101, b"\x08")])  # slave 1: port 1 open
    assert send(seg, [dg.build(dg.Cmd.BRD, 0, 0, bytes(1))]) is None
    # the slaves still process it on its way: a reset of the loop settings takes effect
    assert send(seg, [dg.build(dg.Cmd.BWR, 0, 0x0101, b"\x00")]) is None
    assert brd_wkc(seg) == (2, topology.EXIT_MAIN)


# ----------------------------------------------------------------- junctions

JUNCTION = """
slaves:
  - device: echo
    serial: 1
    port3:
      - {device: echo, serial: 2}
      - {device: echo, serial: 3}
    port2:
      - {device: echo, serial: 6}
  - {device: echo, serial: 4}
  - device: echo
    serial: 5
"""


def junction() -> tuple[SegmentConfig, Segment]:
    cfg = parse_segment(yaml.safe_load(JUNCTION), "j.yaml")
    return cfg, build_segment(cfg, ManualClock(1_000_000_000))


def test_junction_slaves_are_numbered_in_processing_order() -> None:
    cfg, seg = junction()
    # 0 -> 3 -> 1 -> 2: the junction, its port-3 line, the main line, its port-2 line
    assert [s.serial for s in cfg.slaves] == [1, 2, 3, 4, 5, 6]
    assert cfg.wiring[0] == (topology.MAIN, 4 * 3, 4 * 5, 4 * 1)
    assert cfg.ports == (0xF, 0x3, 0x3, 0x3, 0x3, 0x3)
    assert brd_wkc(seg) == (6, topology.EXIT_MAIN)
    number_stations(seg, 6)
    assert stations(seg) == [0x1000 + k for k in range(6)]


def test_junction_dl_status_and_receive_times() -> None:
    _, seg = junction()
    r = send(seg, [dg.build(dg.Cmd.APRD, 0, 0x0110, bytes(2))])
    assert r is not None
    # every port has a link and is open with communication
    assert r[0][0].data == bytes([0xF0 | 0x03, 0xAA])
    send(seg, [dg.build(dg.Cmd.BWR, 0, 0x0900, bytes(4))])
    p0, p1, p2, p3 = struct.unpack_from("<4I", seg.escs[0].mem, 0x0900)
    assert p0 < p3 < p1 < p2  # the frame comes back at 3, then 1, then 2
    assert p3 - p0 == 4 * HOP + TURN  # two slaves on port 3, there and back
    assert p1 - p3 == 4 * HOP + TURN
    assert p2 - p1 == 2 * HOP + TURN


def test_junction_branch_cut_hides_it_and_renumbers() -> None:
    _, seg = junction()
    faults = FaultEngine(seg)
    faults.set_cable(0, 3, False)  # the port-3 line's cable
    assert brd_wkc(seg)[0] == 4
    number_stations(seg, 4)
    # slaves 1 and 2 are gone: the main line and port 2's line move up
    assert stations(seg) == [0x1000, 0, 0, 0x1001, 0x1002, 0x1003]
    assert seg.escs[0].mem[0x0313] == 1  # lost link counter, port 3


def test_topology_errors_are_one_line() -> None:
    bad = {"slaves": [{"device": "echo", "count": 2, "port3": [{"device": "echo"}]}]}
    with pytest.raises(UserError, match=r"slaves\[0\].count: a junction"):
        parse_segment(bad, "x.yaml")
    with pytest.raises(UserError, match=r"slaves\[0\].port2: expected a non-empty list"):
        parse_segment({"slaves": [{"device": "echo", "port2": {}}]}, "x.yaml")
    with pytest.raises(UserError, match="out_iface: expected an interface name"):
        parse_segment({"slaves": [{"device": "echo"}], "out_iface": 3}, "x.yaml")


def test_describe_draws_the_tree() -> None:
    _cfg, seg = junction()
    names = [str(i) for i in range(6)]
    assert topology.describe(seg.wiring, names) == [
        "master - 0 - 3 - 4",
        "0.port3 - 1 - 2",
        "0.port2 - 5",
    ]
    assert topology.describe(topology.linear(2, out=True), ["0", "1"]) == ["master - 0 - 1 - out"]


# ----------------------------------------------------------------- cable redundancy


def test_ring_whole_secondary_passes_untouched() -> None:
    seg = line(4, out=True)
    assert brd_wkc(seg) == (4, topology.EXIT_OUT)  # the primary frame leaves at NIC1
    raw = bytearray(dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0, bytes(1))]))
    before = bytes(raw)
    assert seg.process(raw, 14, len(raw), 0, 1)
    assert (bytes(raw), seg.exit, seg.processed) == (before, topology.EXIT_MAIN, False)


def test_break_splits_the_ring_and_the_far_side_processes_in_wire_order() -> None:
    seg = line(4, out=True)
    number_stations(seg, 4)
    FaultEngine(seg).set_cable(1, 1, False)  # the cable between slaves 1 and 2
    assert brd_wkc(seg) == (2, topology.EXIT_MAIN)  # NIC0's frame: slaves 0, 1
    # NIC1's frame: unprocessed to slave 2, whose closed port 0 turns it into its
    # processing unit; then 2, 3 in wire order and out at NIC1 again
    r = send(
        seg,
        [
            dg.build(dg.Cmd.APRD, 0, 0x0010, bytes(2), more=True),
            dg.build(dg.Cmd.APRD, 0xFFFF, 0x0010, bytes(2), more=True),
            dg.build(dg.Cmd.FPRD, 0x1003, 0x0010, bytes(2)),
        ],
        entry=1,
    )
    assert r is not None
    replies, exit_ = r
    assert exit_ == topology.EXIT_OUT
    assert [x.data for x in replies] == [b"\x02\x10", b"\x03\x10", b"\x03\x10"]
    assert [x.wkc for x in replies] == [1, 1, 1]
    # slave 2's port 0 is closed (no link): it marks the frame circulating
    assert all(x.flags & dg.CIRCULATING for x in replies)
    assert seg.processed
    # the main route is served again for the next primary frame
    assert brd_wkc(seg) == (2, topology.EXIT_MAIN)
    FaultEngine(seg).set_cable(1, 1, True)  # heal
    assert brd_wkc(seg) == (4, topology.EXIT_OUT)
    assert brd_wkc(seg, entry=1) == (0, topology.EXIT_MAIN)


def test_soem_resend_combines_both_halves() -> None:
    """SOEM resends the primary frame it got back on NIC1; the two halves add up."""
    seg = line(4, out=True)
    number_stations(seg, 4)
    FaultEngine(seg).set_cable(1, 1, False)
    datagrams = [dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))]
    raw = bytearray(dg.ethernet_frame(datagrams))
    assert seg.process(raw, 14, len(raw), 0, 0) and seg.exit == topology.EXIT_MAIN
    assert seg.process(raw, 14, len(raw), 0, 1) and seg.exit == topology.EXIT_OUT
    assert decode(bytes(raw), 14)[0].wkc == 4


# ----------------------------------------------------------------- the out interface


def test_out_link_carrier_is_port_1s_link() -> None:
    seg = line(2, out=True)
    last = seg.escs[1]
    assert last.mem[0x0110] & 0x20 and not last.mem[0x0111] & 0x04  # link, open
    seg.set_out_link(False)
    assert brd_wkc(seg) == (2, topology.EXIT_MAIN)  # the loop closes at the last slave
    assert not last.mem[0x0110] & 0x20 and last.mem[0x0111] & 0x04
    assert last.mem[0x0311] == 1  # lost link counter, port 1
    seg.set_out_link(True)
    assert brd_wkc(seg) == (2, topology.EXIT_OUT)


def _chain_frame(a: Segment, b: Segment, clock: ManualClock, datagrams: list[bytes]) -> Any:
    """A frame through daemon A (out link) into B and back through A, 5 us per hop
    between the processes."""
    raw = bytearray(dg.ethernet_frame(datagrams))
    assert a.process(raw, 14, len(raw), clock.now_ns(), 0) and a.exit == topology.EXIT_OUT
    a.after_reply()
    clock.advance(5_000)
    assert b.process(raw, 14, len(raw), clock.now_ns(), 0) and b.exit == topology.EXIT_MAIN
    b.after_reply()
    clock.advance(5_000)
    assert a.process(raw, 14, len(raw), clock.now_ns(), 1) and a.exit == topology.EXIT_MAIN
    assert not a.processed  # back through A unprocessed
    return decode(bytes(raw), 14)


def test_two_segments_chained_are_one_line() -> None:
    clock = ManualClock(1_000_000_000)
    a = line(2, out=True, clock=clock)
    b = line(3, clock=clock)
    assert _chain_frame(a, b, clock, [dg.build(dg.Cmd.BRD, 0, 0, bytes(1))])[0].wkc == 5
    for k in range(5):
        r = _chain_frame(
            a,
            b,
            clock,
            [dg.build(dg.Cmd.APWR, (-k) & 0xFFFF, 0x0010, struct.pack("<H", 0x100 + k))],
        )
        assert r[0].wkc == 1
    assert stations(a) + stations(b) == [0x100, 0x101, 0x102, 0x103, 0x104]
    # receive times: the last slave of A sees the frame back at port 1 when it comes
    # back from B (10 us of real time later)
    _chain_frame(a, b, clock, [dg.build(dg.Cmd.BWR, 0, 0x0900, bytes(4))])
    p0, p1 = struct.unpack_from("<II", a.escs[1].mem, 0x0900)
    assert p1 - p0 == 10_000 - HOP  # it reached slave 1 one hop after the daemon
    p0, p1 = struct.unpack_from("<II", a.escs[0].mem, 0x0900)
    assert p1 - p0 == 10_000 + HOP
    assert not a.ctx.latch_wait


def test_ctl_status_table_shows_junction_ports_and_the_tree() -> None:
    from ecatsim.ctl.server import ControlSocket
    from ecatsim.ctl.table import format_status

    _, seg = junction()
    status = ControlSocket.status(_StatusOnly(seg))  # type: ignore[arg-type]
    text = format_status(status)
    assert "port 3" in text.splitlines()[0]
    assert text.splitlines()[1].split()[6:10] == ["link/open"] * 4
    assert "topology (port 0 -> 3 -> 1 -> 2):\n  master - 0 - 3 - 4\n  0.port3 - 1 - 2" in text
    assert "lost 0+0+0+0" in text


class _StatusOnly:
    """What ControlSocket.status reads of itself."""

    def __init__(self, seg: Segment) -> None:
        self.segment = seg
        self.faults = FaultEngine(seg)
        self.doors = None


def test_daemon_sends_each_frame_where_its_route_leaves() -> None:
    """The daemon with an out link (loopback links in process): a frame from the master
    leaves on the out link marked processed; the same frame coming back on the out link
    leaves on the daemon's link unmarked again; no carrier closes the loop at home."""
    from ecatsim.ethercat.daemon import Daemon, OutPort
    from ecatsim.link.loopback import LoopbackLink

    seg = line(2, out=True)
    seg.set_out_link(False)
    main, far = LoopbackLink(), LoopbackLink()
    carrier = [True]
    d = Daemon(main, seg, out=OutPort(far, lambda: carrier[0]))
    d._service_timers()  # the first look at the carrier
    assert seg.out_up
    buf = bytearray(2048)
    frame = dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0, bytes(1))])
    main.master_send(frame)
    assert d.handle_one(buf)
    went = far.master_recv()
    assert went is not None and main.master_recv() is None
    assert went[6] & 0x02 and decode(went, 14)[0].wkc == 2
    far.master_send(went)  # the next daemon's reply comes back on the out link
    assert d.handle_out(buf)
    back = main.master_recv()
    assert back == went and far.master_recv() is None
    carrier[0] = False
    d.out.look_ns = 0  # type: ignore[union-attr]
    d._service_timers()
    main.master_send(frame)
    assert d.handle_one(buf)
    home = main.master_recv()
    assert home is not None and decode(home, 14)[0].wkc == 2


def test_the_work_after_a_reply_stops_for_a_frame_coming_back_on_the_out_link() -> None:
    """With an out link the frame a daemon passed on comes back there, and the master waits
    for it: the work after a reply looks on both links for a waiting frame (P19, L9)."""
    from ecatsim.ethercat.daemon import Daemon, OutPort
    from tests.support.socketlink import SocketLink

    seg = line(2, out=True)
    main, far = SocketLink(), SocketLink()
    d = Daemon(main, seg, out=OutPort(far, lambda: True))
    d.probe_frames()
    waiting = seg.schedule.frame_waiting
    assert waiting is not None and d.frame_fds() == (main.fileno(), far.fileno())
    assert not waiting()
    far.master_send(b"\x00" * 60)  # the next daemon's reply
    assert waiting()
    assert far.recv_into(bytearray(64)) == 60
    assert not waiting()
    main.master_send(b"\x00" * 60)  # a frame from the master
    assert waiting()
    main.close()
    far.close()


def test_a_dl_control_write_that_keeps_the_loop_settings_keeps_the_routes() -> None:
    """SOEM's ec_config_init writes 0x0100 (the forwarding rule) of every slave: the routes
    are compiled again only when the loop settings (0x0101) change. Ref: TMC8460 §5.17."""
    seg = line(3)
    routes = seg.routes[0]
    assert routes is not None
    got = send(seg, [dg.build(dg.Cmd.BWR, 0, 0x0100, bytes(2))])
    assert got is not None and got[0][0].wkc == 3
    send(seg, [dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    assert seg.routes[0] is routes and not seg.ctx.topology_dirty
    assert [bytes(e.mem[0x0100:0x0104]) for e in seg.escs] == [b"\x00\x00\x07\x00"] * 3
    # the last slave's port 1 closed (loop 0x0101 bits 2-3 = 2): compiled again, same order
    send(seg, [dg.build(dg.Cmd.APWR, (-2) & 0xFFFF, 0x0101, b"\x08")])
    send(seg, [dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    again = seg.routes[0]
    assert again is not None and again is not routes and again.order == routes.order
