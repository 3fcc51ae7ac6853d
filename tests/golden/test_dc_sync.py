"""SYNC0 in process: pulses on the DC time grid, DC-synchronous outputs applied and inputs
captured at the pulse, and frames and pulses handled in the order they happened even when
the daemon gets to both late. Ref: TMC8460 §5.50.4; ETG.1000.6 §5.3; decisions DC2-DC4."""

from __future__ import annotations

import struct

from ecatsim.ethercat.daemon import Daemon
from ecatsim.link.loopback import LoopbackLink
from ecatsim.wire import datagram as dg
from tests.perf.hotpath import configure_to_op
from tests.support.tinymaster import TinyMaster, decode, segment_of

MS = 1_000_000
OUT, IN = 12, 17  # the echo device's process image (TMC8670 default PDOs)


class DcBench:
    """One echo slave in OP with SYNC0 every 1 ms, served by the daemon loop."""

    def __init__(self) -> None:
        self.seg, self.clock = segment_of(1)
        t = TinyMaster(self.seg)
        configure_to_op(t, 1)
        self.link = LoopbackLink()
        self.daemon = Daemon(self.link, self.seg)
        self.buf = bytearray(2048)
        sys_now = struct.unpack("<Q", t.aprd(0, 0x0910, 8).data)[0]
        self.start = sys_now + 2 * MS
        t.apwr(0, 0x09A0, struct.pack("<I", MS))
        t.apwr(0, 0x0990, struct.pack("<Q", self.start))
        t.apwr(0, 0x0981, b"\x03")  # SYNC unit + SYNC0
        t0 = self.seg.escs[0].dc.sync0_deadline()
        assert t0 is not None
        self.t0: int = t0

    def lrw(self, target: int, rx_ns: int) -> int:
        """A cyclic LRW that arrived at ``rx_ns`` (handled whenever the clock says);
        returns the echoed 6064h from the inputs it read."""
        out = struct.pack("<HiHi", 0x0F, target, 0, 0)
        frame = dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, 0, out + bytes(IN))])
        self.link.master_send(frame)
        self.link.rx_ns = rx_ns
        assert self.daemon.handle_one(self.buf)
        reply = decode(self.link.master_recv() or b"", 14)[0]
        assert reply.wkc == 3
        return int(struct.unpack_from("<i", reply.data, OUT + 3)[0])  # 6041h, 6061h, 6064h

    def at(self, t_ns: int) -> None:
        """The host clock reaches t_ns; the daemon's timers run."""
        self.clock.t = t_ns
        self.daemon._service_timers()


def test_pulses_follow_the_dc_grid() -> None:
    b = DcBench()
    esc = b.seg.escs[0]
    b.at(b.t0 - 1)
    assert b.seg.schedule.sync0_ticks == 0
    b.at(b.t0)
    assert b.seg.schedule.sync0_ticks == 1 and esc.mem[0x098E] & 0x01
    assert esc.dc.sync0_deadline() == b.t0 + MS
    b.at(b.t0 + 3 * MS + 10)  # three more due: each fired, none skipped
    assert b.seg.schedule.sync0_ticks == 4
    assert esc.dc.sync0_deadline() == b.t0 + 4 * MS


def test_outputs_apply_at_the_next_pulse_and_inputs_are_captured_there() -> None:
    b = DcBench()
    b.at(b.t0)
    b.clock.t = b.t0 + MS // 2
    assert b.lrw(111, b.clock.t) == 0  # the inputs are those captured at the last pulse
    assert b.lrw(111, b.clock.t) == 0  # not yet applied: DC synchronous
    b.at(b.t0 + MS)
    b.clock.t = b.t0 + MS + MS // 2
    assert b.lrw(222, b.clock.t) == 111


def test_a_late_daemon_keeps_the_order_of_frames_and_pulses() -> None:
    """Frame A before pulse 1, frame B after it, the daemon gets to B only later: pulse 1
    still applies A's target, B's waits for pulse 2."""
    b = DcBench()
    b.at(b.t0)
    b.clock.t = b.t0 + MS // 2
    b.lrw(111, b.clock.t)  # frame A
    b.clock.t = b.t0 + MS + 600_000  # the daemon was away past pulse 1 ...
    assert b.lrw(222, b.t0 + MS + 200_000) == 111  # ... frame B arrived after pulse 1
    b.at(b.t0 + 2 * MS)
    b.clock.t = b.t0 + 2 * MS + 500_000
    assert b.lrw(333, b.clock.t) == 222
    assert b.seg.schedule.sync0_ticks == 3


def sys_time(b: DcBench) -> int:
    return b.seg.escs[0].dc.system_time(b.clock.t)


def test_sync1_after_sync0_by_its_cycle_time() -> None:
    """SOEM's dc_sync01: SYNC1 cycle time below the SYNC0 cycle is a shift after each
    SYNC0; a multiple of it makes SYNC1 every n-th SYNC0 (decision DC5)."""
    b = DcBench()
    t = TinyMaster(b.seg)
    m = b.seg.escs[0].mem
    t.apwr(0, 0x0981, b"\x00")
    t.apwr(0, 0x09A4, struct.pack("<I", 300_000))
    t.apwr(0, 0x0981, b"\x07")
    assert t.aprd(0, 0x0984, 1).data == b"\x03"  # first SYNC0 and SYNC1 pending
    b.at(b.t0)
    assert struct.unpack("<Q", t.aprd(0, 0x0998, 8).data)[0] == b.start + 300_000
    assert t.aprd(0, 0x098F, 1).data == b"\x00" and t.aprd(0, 0x0984, 1).data == b"\x02"
    b.at(b.t0 + 300_000)
    assert t.aprd(0, 0x098F, 1).data == b"\x01" and t.aprd(0, 0x0984, 1).data == b"\x00"
    # every second SYNC0
    t.apwr(0, 0x0981, b"\x00")
    m[0x098F] = 0
    start = sys_time(b) + 2 * MS
    t.apwr(0, 0x09A4, struct.pack("<I", 2 * MS))
    t.apwr(0, 0x0990, struct.pack("<Q", start))
    t.apwr(0, 0x0981, b"\x07")
    t0 = b.seg.escs[0].dc.sync0_deadline()
    assert t0 is not None
    b.at(t0)
    assert struct.unpack("<Q", t.aprd(0, 0x0998, 8).data)[0] == start  # with this SYNC0
    b.at(t0 + 1)
    assert m[0x098F] == 0x01
    m[0x098F] = 0
    b.at(t0 + MS + 1)
    assert m[0x098F] == 0x00  # not with the next SYNC0 ...
    b.at(t0 + 2 * MS + 1)
    assert m[0x098F] == 0x01  # ... but with the one after


def test_latch_single_event_and_continuous() -> None:
    """LATCH1 (SII 0x0151 bit 6 = 0: a latch input) captures the system time of edges.
    Ref: TMC8460 §5.50.5 Tables 114-121."""
    b = DcBench()
    t = TinyMaster(b.seg)
    esc = b.seg.escs[0]
    assert t.aprd(0, 0x0151, 1).data[0] & 0x40 == 0
    t.apwr(0, 0x09A9, b"\x01")  # LATCH1 positive edge: single event
    b.clock.t += 1000
    esc.latch_input(1, True, b.clock.t)
    first = sys_time(b)
    b.clock.t += 5000
    esc.latch_input(1, False, b.clock.t)
    neg = sys_time(b)
    esc.latch_input(1, True, b.clock.t + 7000)  # ignored: single event, not read yet
    assert t.aprd(0, 0x09AF, 1).data == b"\x05"  # event positive edge, pin high
    assert esc.mem[0x0210] & 0x01  # ECAT event: DC latch
    assert struct.unpack("<Q", t.aprd(0, 0x09C8, 8).data)[0] == neg  # continuous: latest
    assert struct.unpack("<Q", t.aprd(0, 0x09C0, 8).data)[0] == first
    assert t.aprd(0, 0x09AF, 1).data == b"\x04"  # read out: the event flag is cleared
    assert not esc.mem[0x0210] & 0x01
    esc.latch_input(1, False, b.clock.t + 8000)
    esc.latch_input(1, True, b.clock.t + 9000)  # the next single event
    assert t.aprd(0, 0x09AF, 1).data == b"\x05"
    assert struct.unpack("<Q", t.aprd(0, 0x09C0, 8).data)[0] == esc.dc.system_time(b.clock.t + 9000)
    # 0x0151 bit 2 = 1 makes SYNC0 an output, and LATCH0 still latches: the TMC8460 has
    # concurrent SYNC outputs and LATCH inputs (Table 42 note *)
    assert t.aprd(0, 0x0151, 1).data[0] & 0x04
    esc.latch_input(0, True, b.clock.t + 10_000)
    assert t.aprd(0, 0x09AE, 1).data == b"\x04"  # continuous: pin high, no event flag
    pos0 = esc.dc.system_time(b.clock.t + 10_000)
    assert struct.unpack("<Q", t.aprd(0, 0x09B0, 8).data)[0] == pos0


def test_reset_stops_the_sync_unit() -> None:
    """A power cycle or 'RES' reset returns 0x0981 to 0: no more pulses until activated."""
    b = DcBench()
    b.at(b.t0)
    assert b.seg.schedule.sync0_ticks == 1
    b.seg.escs[0].hardware_reset()
    b.at(b.t0 + 5 * MS)
    assert b.seg.schedule.sync0_ticks == 1
    assert b.seg.escs[0].dc.sync0_deadline() is None
    assert b.seg.schedule.next_deadline() is None


def test_pulse_hint_follows_an_offset_change() -> None:
    """Frames far from a pulse skip the per-slave check; a new system time offset (0x0920)
    moves the deadlines and is honoured at once (Ref: TMC8460 §5.50.2 Table 96)."""
    b = DcBench()
    t = TinyMaster(b.seg)
    b.at(b.t0)
    assert b.seg.schedule.sync0_ticks == 1
    off = struct.unpack("<Q", t.aprd(0, 0x0920, 8).data)[0]
    t.apwr(0, 0x0920, struct.pack("<Q", off + 600_000))  # system time 0.6 ms ahead
    d = b.seg.escs[0].dc.sync0_deadline()
    assert d is not None and d == b.t0 + MS - 600_000
    b.lrw(1, d + 1000)  # a frame just after the moved pulse: the pulse comes first
    assert b.seg.schedule.sync0_ticks == 2


def test_acknowledge_mode_clears_the_sync_state_on_pdi_read() -> None:
    """Pulse length 0 (0x0982): acknowledge mode, the SYNC0 state stays set until the PDI
    reads 0x098E. With a pulse length the PDI read leaves it. Ref: TMC8460 Tables 106, 108."""
    from ecatsim.esc.pdi import Pdi

    b = DcBench()
    esc = b.seg.escs[0]
    pdi = Pdi(esc)
    assert esc.mem[0x0982] | esc.mem[0x0983]  # the TMC8670 SII sets a 1 us pulse
    b.at(b.t0)
    assert esc.mem[0x098E] & 0x01
    pdi.u8(0x098E)
    assert esc.mem[0x098E] & 0x01  # pulse mode: the read does not acknowledge
    esc.mem[0x0982:0x0984] = b"\x00\x00"  # acknowledge mode
    pdi.u8(0x098E)
    assert not esc.mem[0x098E] & 0x01
