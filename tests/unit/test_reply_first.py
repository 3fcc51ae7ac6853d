"""Reply first, react after (decisions P19, P20): the ESC's part of a broadcast is a copy
plus the side effects that change state, and the firmware's reactions run after the reply,
stopping for a frame that comes meanwhile and going on after its reply, with the same AL
states and codes a polling master reads."""

from __future__ import annotations

import struct

from ecatsim.esc.core import Esc
from ecatsim.esc.units import tables
from ecatsim.wire import datagram as dg
from ecatsim.wire.frame import ecat_offset
from tests.perf.hotpath import MS, CspCycle, configure_to_op, op_segment
from tests.support.tinymaster import TinyMaster, segment_of

AL_STATUS, AL_EVENT = 0x0130, 0x0220


def bwr_only(m: TinyMaster, ado: int, data: bytes) -> int:
    """A BWR with no service after it (the reply is out, the firmware has not acted)."""
    return m.one(dg.build(dg.Cmd.BWR, 0, ado, data), service=False).wkc


def brd_only(m: TinyMaster, ado: int, n: int) -> tuple[bytes, int]:
    r = m.one(dg.build(dg.Cmd.BRD, 0, ado, bytes(n)), service=False)
    return r.data, r.wkc


def al_status(m: TinyMaster, n: int) -> list[int]:
    return [struct.unpack_from("<H", m.seg.escs[i].mem, AL_STATUS)[0] for i in range(n)]


def test_the_work_after_a_reply_stops_for_a_waiting_frame_and_goes_on_after_it() -> None:
    m, _, _ = op_segment(4)
    seg = m.seg
    assert al_status(m, 4) == [8, 8, 8, 8]
    waiting = [True]
    seg.schedule.frame_waiting = lambda: waiting[0]
    seg.schedule.probe_ns = 0  # look after every slave
    assert bwr_only(m, 0x0120, b"\x02\x00") == 4  # PREOP
    seg.service()  # the first slave acts, then the waiting frame comes first
    assert seg.schedule.yielded == 1
    assert al_status(m, 4) == [2, 8, 8, 8]
    # the frame that waited: a polling master sees the slaves that have acted
    assert brd_only(m, AL_STATUS, 2) == (b"\x0a\x00", 4)  # 2 | 8: ORed over the slaves
    assert [bool(seg.escs[i].mem[AL_EVENT] & 0x01) for i in range(4)] == [False, True, True, True]
    waiting[0] = False
    seg.service()  # after that frame's reply: the rest
    assert seg.schedule.yielded == 1
    assert al_status(m, 4) == [2, 2, 2, 2]
    assert [seg.escs[i].mem[AL_EVENT] & 0x01 for i in range(4)] == [0, 0, 0, 0]
    assert m.brd(AL_STATUS, 2).data == b"\x02\x00"


def test_without_a_waiting_frame_the_work_runs_to_its_end() -> None:
    m, _, _ = op_segment(3)
    m.seg.schedule.frame_waiting = lambda: False
    m.seg.schedule.probe_ns = 0
    m.bwr(0x0120, b"\x01\x00")
    assert al_status(m, 3) == [1, 1, 1]
    assert m.seg.schedule.yielded == 0


def test_the_first_look_comes_after_the_first_slave_whatever_probe_ns() -> None:
    """The frames a master sends back to back wait for one slave's work, not for probe_ns
    of it (decision P98): a look after the first slave, then every probe_ns (10 s here:
    none more)."""
    m, _, _ = op_segment(4)
    seg = m.seg
    waiting, asked = [False], [0]

    def frame_waits() -> bool:
        asked[0] += 1
        return waiting[0]

    seg.schedule.frame_waiting = frame_waits
    seg.schedule.probe_ns = 10_000_000_000
    assert bwr_only(m, 0x0120, b"\x02\x00") == 4  # PREOP
    seg.service()  # no frame waits: one look, after the first slave; the rest runs on
    assert (asked[0], seg.schedule.yielded, al_status(m, 4)) == (1, 0, [2, 2, 2, 2])
    waiting[0] = True
    assert bwr_only(m, 0x0120, b"\x04\x00") == 4  # SAFEOP
    seg.service()  # a frame waits: found at the look after the first slave
    assert (asked[0], seg.schedule.yielded) == (2, 1)
    assert al_status(m, 4) == [4, 2, 2, 2]


def test_clearing_the_fmmus_by_broadcast_clears_the_maps() -> None:
    m, _, _ = op_segment(3)
    assert all(len(e.fmmus) == 2 for e in m.seg.escs)
    r = m.bwr(0x0600, bytes(256))
    assert r.wkc == 3
    assert [e.fmmus for e in m.seg.escs] == [(), (), ()]
    assert m.lrw(0, bytes(3 * 29)).wkc == 0  # nothing maps the logical space any more
    r = m.bwr(0x0600, bytes(256))  # again, over what is already clear
    assert (r.wkc, [e.fmmus for e in m.seg.escs]) == (3, [(), (), ()])


def test_a_write_of_the_same_fmmu_bytes_keeps_the_maps() -> None:
    m, _, _ = op_segment(2)
    before = [e.fmmus for e in m.seg.escs]
    cfg = bytes(m.seg.escs[0].mem[0x0600:0x0620])
    m.apwr(0, 0x0600, cfg)
    assert m.seg.escs[0].fmmus == before[0]
    assert m.lrw(0, bytes(2 * 29)).wkc == 6  # both slaves: outputs written, inputs read


def test_a_repeated_al_control_write_is_a_new_request_each_time() -> None:
    """AL control acts on every write, not on a change: the same request twice raises the
    AL event twice (TMC8460 §5.20)."""
    seg, _ = segment_of(2)
    m = TinyMaster(seg)
    m.bwr(0x0120, b"\x11\x00")
    for _ in range(2):
        bwr_only(m, 0x0120, b"\x01\x00")
        assert [e.mem[AL_EVENT] & 0x01 for e in seg.escs] == [1, 1]
        seg.service()
        assert [e.mem[AL_EVENT] & 0x01 for e in seg.escs] == [0, 0]


def test_sm_config_written_while_enabled_keeps_its_value() -> None:
    m, _, _ = op_segment(1)
    old = bytes(m.seg.escs[0].mem[0x0810:0x0818])
    m.bwr(0x0810, struct.pack("<HHB", 0x1400, 4, 0x20))  # SM2 is enabled: refused
    assert bytes(m.seg.escs[0].mem[0x0810:0x0818]) == old


def test_the_fmmu_hook_is_one_block_and_acts_on_a_change_only() -> None:
    t = tables()
    assert t.ecat_w[0x0600] == (Esc._ec_fmmu, 0x0600, 96)
    assert t.ecat_w[0x065C] == (Esc._ec_fmmu, 0x0600, 96)
    assert t.ecat_w_change[0x0600] == 1 and t.ecat_w_change[0x0806] == 1
    assert t.ecat_w_change[0x0120] == 0  # AL control: every write
    assert t.ecat_w_change[0x0502] == 0  # EEPROM control: every write
    assert t.ecat_w_change[0x0910] == 0  # the DC time loop: every write


def test_the_sm_hook_is_one_block_for_the_ecat_writes() -> None:
    """The SyncManagers' start, length, control and activate registers: one ECAT write
    hook for the block (P58); the PDI read of an activate register keeps its own hook."""
    t = tables()
    for a in (0x0800, 0x0802, 0x0804, 0x082C):
        assert t.ecat_w[a] == (Esc._ec_sm, 0x0800, 48)
    assert t.ecat_w[0x0806] == t.ecat_w[0x082E] == (Esc._ec_sm_activate, 0x0800, 48)
    assert t.ecat_w[0x0805] is None and t.ecat_w[0x0807] is None  # status, PDI control
    assert t.pdi_r[0x0816] == (Esc._pr_sm_activate, 0x0816, 1)
    assert t.pdi_r[0x0810] is None
    assert t.ecat_w_change[0x0800] == 1 and t.ecat_w_change[0x0806] == 1


def test_clearing_the_configured_sms_by_broadcast_disables_them_and_keeps_their_config() -> None:
    """A BWR of 48 zero bytes to 0x0800 over slaves in OP: every SM is disabled (its
    window gone, the FMMUs no longer routed to it), start, length and control keep the
    values they had while enabled, and AL event 0x0220.4 is raised once per slave.
    Ref: TMC8460 §5.49 Tables 86-88, 90."""
    m, _, _ = op_segment(3)
    before = [bytes(e.mem[0x0800:0x0830]) for e in m.seg.escs]
    assert all(len(e.sm_windows) == 4 for e in m.seg.escs)
    assert bwr_only(m, 0x0800, bytes(48)) == 3
    for e, old in zip(m.seg.escs, before, strict=True):
        assert e.sm_windows == ()
        assert all(f.sm is None for f in e.fmmus)
        assert [sm.enabled for sm in e.sm] == [False] * 6
        for n in range(4):  # the four SMs that were enabled: their configuration stays
            a = 8 * n
            assert bytes(e.mem[0x0800 + a : 0x0805 + a]) == old[a : a + 5]
            assert e.mem[0x0806 + a] == 0
        assert e.mem[AL_EVENT] & 0x10 == 0x10
    # again, over disabled SMs: now the configuration is taken, and no activate byte changed
    for e in m.seg.escs:
        e.clr_al_event(0x10)
    assert bwr_only(m, 0x0800, bytes(48)) == 3
    assert [bytes(e.mem[0x0800:0x0830:8]) for e in m.seg.escs] == [bytes(6)] * 3
    assert [e.mem[AL_EVENT] & 0x10 for e in m.seg.escs] == [0, 0, 0]


def test_one_write_of_an_sm_sets_its_config_and_enables_it() -> None:
    """Start, length, control and activate in one write to a disabled SM: the SM starts
    with the new values (they are taken before the activate byte). Ref: §5.49 Table 90."""
    seg, _ = segment_of(1)
    m = TinyMaster(seg)
    e = seg.escs[0]
    cfg = struct.pack("<HHBBBB", 0x1800, 6, 0x64, 0, 0x01, 0)
    assert m.one(dg.build(dg.Cmd.APWR, 0, 0x0820, cfg), service=False).wkc == 1
    sm = e.sm[4]
    assert (sm.start, sm.length, sm.control, sm.active) == (0x1800, 6, 0x64, True)
    assert e.sm_windows[-1][:2] == (0x1800, 0x1806)
    assert e.mem[AL_EVENT] & 0x10 == 0x10  # until the firmware reads the activate byte
    m.apwr(0, 0x0826, b"\x00")  # the activate byte alone disables it
    assert not sm.active and all(w[2] is not sm for w in e.sm_windows)


def test_broadcast_read_ors_every_slave() -> None:
    seg, _ = segment_of(3)
    m = TinyMaster(seg)
    for i, v in enumerate((0x01, 0x10, 0x80)):
        seg.escs[i].mem[0x0F80] = v  # user RAM
    r = m.one(dg.build(dg.Cmd.BRD, 0, 0x0F80, b"\x02\x00"))
    assert (r.data, r.wkc, r.adp) == (b"\x93\x00", 3, 3)


def test_configure_to_op_still_reaches_op_on_every_slave() -> None:
    seg, _ = segment_of(5, device="tmc8670")
    m = TinyMaster(seg)
    configure_to_op(m, 5)
    assert al_status(m, 5) == [8] * 5


def test_dc_time_loops_wait_for_the_reply() -> None:
    """The FRMW of 0x0910 (the frame's last datagram): the reply carries the reference's
    time and WKC = number of slaves at once; the other slaves' time loops run in
    after_reply(), with the results they have when run inline (decision P7)."""
    a, b = CspCycle(3), CspCycle(3)
    b.seg.reply_first = False  # inline, in the walk
    for c in (a, b):
        c.pulse()
        c.clock.t = c.t + MS // 2
    raw = bytearray(a.frame(0x0F))
    off = ecat_offset(raw, len(raw), True)
    rebased = [e.dc.t_ref for e in a.seg.escs]  # each time loop rebases its clock
    assert a.seg.process(raw, off, len(raw), a.clock.t)
    assert a.seg._dc_pending == 8  # waiting: 8 bytes of time
    assert [e.dc.t_ref for e in a.seg.escs] == rebased  # not yet
    p = off + 2 + 10 + 3 * (12 + 17) + 2  # behind the LRW (header, images, WKC)
    assert raw[p] == dg.Cmd.FRMW
    assert struct.unpack_from("<H", raw, p + 10 + 8)[0] == 3
    a.seg.after_reply()
    assert a.seg._dc_pending == 0
    after = [e.dc.t_ref for e in a.seg.escs]
    assert after[0] == rebased[0]  # the reference does not correct itself
    assert all(t != r for t, r in zip(after[1:], rebased[1:], strict=True))
    inline = bytearray(b.frame(0x0F))
    assert b.seg.process(inline, off, len(inline), b.clock.t)
    assert b.seg._dc_pending == 0
    assert bytes(inline) == bytes(raw)
    assert [e.dc.t_ref for e in b.seg.escs] == after
    assert [bytes(e.mem[0x0910:0x0940]) for e in b.seg.escs] == [
        bytes(e.mem[0x0910:0x0940]) for e in a.seg.escs
    ]
