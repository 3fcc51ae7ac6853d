"""The compiled responder against the daemon's Python path, over whole DC cycles: two
receive and send in compiled code) and one through Daemon.handle_one, run the same
frames and must agree on every byte of ESC memory, every SM and event state, every OD
value, the drive's state and every reply, through enable, motion, mode changes, a fault
with its emergency, SAFEOP and back. (The core itself is one source: the compiled and
pure-Python cores are compared in tests/unit/test_core_one_source.py.)
Ref: ecatsim/daemon.py Daemon.serve_once, Daemon.handle_frame; decision P9."""

from __future__ import annotations

import random
import struct
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import pytest

from ecatsim import daemon as daemon_mod
from ecatsim.esc import regs
from ecatsim.slave.pdo import Field, codec
from ecatsim.wire import datagram as dg
from ecatsim.wire.frame import ecat_offset
from tests.perf.hotpath import CSP, IN, MS, OUT, CspCycle
from tests.support.compiled import record_results, require_built
from tests.support.fuzz import mutate

CSV, CST = 9, 10
#: the drive's caches (not state of the model)
LOCAL = {"_snapshot_hits", "_published"}


@pytest.fixture(autouse=True)
def _require_compiled() -> None:
    require_built(daemon_mod.responder, "ecatsim.responder")


@pytest.fixture
def answered(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int, int]]:
    """Every result of the compiled responder (responder.serve: code, n, t_rx)."""
    return record_results(monkeypatch, daemon_mod, "responder", "Responder", "serve")


def codes(results: list[tuple[int, int, int]]) -> list[int]:
    return [r[0] for r in results]


FRAME, REPLIED, DROPPED = 2, 3, 4  # the responder's codes (test_serve.py checks them)


def snapshot(c: CspCycle) -> dict[str, Any]:
    """Everything the SYNC0 work can change."""
    seg = c.seg
    out: dict[str, Any] = {"pending": sorted(seg.ctx.pending), "irq": seg.irq}
    out["frames"] = (seg.frames, seg.bad_frames, seg.ctx.frame_no, seg.ctx.t_ns)
    out["dirty"] = (seg.ctx.timers_dirty, seg._dc_pending)
    for esc in c.seg.escs:
        p = esc.position
        out[f"mem{p}"] = bytes(esc.mem)
        out[f"ecat_irq{p}"] = esc.ecat_irq
        out[f"wd{p}"] = (esc.wd.deadline_ns, esc.wd.timeout_ns)
        dc = esc.dc
        out[f"dc{p}"] = (dc.local_ref, dc.t_ref, dc.rate_ppb, dc.spd, dc.moved_ns)
        out[f"wr{p}"] = (esc.wr_s, esc.wr_e)
        out[f"sm{p}"] = [
            (s.w, s.l, s.r, s.r_open, s.w_open, s.status, s.mirror, s.mbx_full) for s in esc.sm
        ]
    for fw in c.seg.firmware:
        p = fw.pdi.position
        out[f"fw{p}"] = (fw.state, fw.error, fw.code, fw.event_mask, fw.pd_masked)
        out[f"mbx{p}"] = list(fw.mbx.out) if fw.mbx is not None else None
        od = fw.od
        assert od is not None
        out[f"od{p}"] = [
            (o.index, sub, e.value) for o in od.objects.values() for sub, e in o.entries.items()
        ]
        d = fw.device
        plain = (int, float, str, bool, type(None), frozenset, set)
        out[f"drive{p}"] = {
            k: v
            for k in dir(d)
            if not k.startswith("__") and isinstance(v := getattr(d, k), plain) and k not in LOCAL
        }
        out[f"servo{p}"] = {
            k: getattr(d.servo, k)  # type: ignore[attr-defined]
            for k in ("angle", "omega", "iq_ma", "iq_integ", "integ", "iq_ref_ma")
        }
    return out


def lockstep(n: int, ecat_irq: bool = False, responder: bool = True) -> tuple[CspCycle, CspCycle]:
    """(through the responder, through Daemon.handle_one with the DC time loops inline)"""
    return (
        CspCycle(n, compiled=True, ecat_irq=ecat_irq, responder=responder),
        CspCycle(n, compiled=False, ecat_irq=ecat_irq),
    )


def agree(a: CspCycle, b: CspCycle) -> None:
    sa, sb = snapshot(a), snapshot(b)
    for key in sa:
        assert sa[key] == sb[key], key


def same(a: CspCycle, b: CspCycle, action: Callable[[CspCycle], bytes | None]) -> None:
    ra, rb = action(a), action(b)
    assert ra == rb
    agree(a, b)


def both(a: CspCycle, b: CspCycle, cw: int | None = None) -> None:
    a.pulse()
    b.pulse()
    agree(a, b)
    same(a, b, lambda c: c.exchange(cw))


def al_request(state: int) -> Callable[[CspCycle], bytes | None]:
    def go(c: CspCycle) -> bytes | None:
        for pos in range(c.n):
            c.master.apwr(pos, regs.AL_CONTROL, struct.pack("<H", state))
        return None

    return go


def test_responder_matches_python_over_the_drive_cycle(
    answered: list[tuple[int, int, int]],
) -> None:
    a, b = lockstep(2)
    same(a, b, lambda c: None)  # enabled by the constructors
    for _ in range(40):  # csp motion
        both(a, b)
    assert codes(answered) == [REPLIED] * 45, "every cyclic frame answered compiled"

    def od(*values: tuple[int, int]) -> Callable[[CspCycle], None]:
        """OD writes on every drive, as an SDO download would make them."""

        def go(c: CspCycle) -> None:
            for fw in c.seg.firmware:
                assert fw.od is not None
                for index, value in values:
                    fw.od.set(index, 0, value)

        return go

    # csv: a slow reverse target plus an offset (the actual speed settles near -1 rpm)
    same(a, b, od((0x60FF, -2), (0x60B1, 1), (0x6060, CSV)))
    for _ in range(60):
        both(a, b)
    same(a, b, od((0x60FF, 0), (0x60B1, 0), (0x6060, CSP)))
    # 0x8F: a fault reset edge, nothing to reset while enabled
    for cw in (0x8F, 0x8F, 0x0F, 0x07, 0x07, 0x0F, 0x0F, 0x02, 0x02, 0x06, 0x07, 0x0F, 0x0F):
        both(a, b, cw)

    def far(by: float) -> Callable[[CspCycle], None]:
        def go(c: CspCycle) -> None:
            for fw in c.seg.firmware:
                fw.device.servo.angle += by  # type: ignore[attr-defined]

        return go

    for cw in (0x00, 0x06, 0x07, 0x0F):  # from wherever the quick stop left it: enabled
        both(a, b, cw)
    same(a, b, od((0x6071, 0), (0x6060, CST)))
    both(a, b)  # the mode changes with this cycle's outputs
    assert a.seg.firmware[0].device.state.name == "OPERATION_ENABLED"  # type: ignore[attr-defined]
    same(a, b, far(-1.0e7))  # a position beyond the 32-bit objects: clamped
    for _ in range(3):
        both(a, b)
    assert a.seg.firmware[0].od.value(0x6064) == -(1 << 31)  # type: ignore[union-attr]
    same(a, b, far(1.0e7))
    same(a, b, od((0x6060, CSP)))
    for cw in (0x06, 0x07, 0x0F, 0x0F):
        both(a, b, cw)

    def fault(active: bool) -> Callable[[CspCycle], None]:
        def go(c: CspCycle) -> None:
            c.seg.firmware[0].device.inject("following_error", active)  # type: ignore[attr-defined]

        return go

    same(a, b, fault(True))  # an emergency is queued: the mailbox part runs in Python
    for _ in range(6):
        both(a, b)

    def take_reply(c: CspCycle) -> None:  # the master reads the emergency from SM1
        c.master.one(dg.build(dg.Cmd.APRD, 0, 0x1080, bytes(128)))

    same(a, b, take_reply)
    assert a.seg.escs[0].al_event() & (regs.EV_SM0 << 1), "SM1 event raised, stays raised"
    for _ in range(3):
        both(a, b)
    same(a, b, fault(False))
    for cw in (0x80, 0x00, 0x06, 0x07, 0x0F, 0x0F):
        both(a, b, cw)
    same(a, b, al_request(0x04))  # SAFEOP: inputs only
    for _ in range(5):
        both(a, b)
    same(a, b, al_request(0x08))
    for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F, 0x0F):
        both(a, b, cw)

    def acknowledge_mode(c: CspCycle) -> None:
        for esc in c.seg.escs:  # pulse length 0: the PDI read acknowledges SYNC0 (Table 106)
            esc.mem[regs.DC_PULSE_LENGTH : regs.DC_PULSE_LENGTH + 2] = b"\x00\x00"

    same(a, b, acknowledge_mode)
    for _ in range(3):
        both(a, b)

    def negative(c: CspCycle) -> None:
        c.amplitude = -20_000  # targets below zero: signed unpacking

    same(a, b, negative)
    for _ in range(10):
        both(a, b)

    def read_open(c: CspCycle) -> None:
        # the master reads SM3's first byte only: its buffer stays open for reading when
        # the firmware writes the next one (the third buffer is used)
        c.master.one(dg.build(dg.Cmd.APRD, 0, 0x1200, bytes(1)), service=False)

    same(a, b, read_open)
    both(a, b)
    both(a, b)
    # a following error window the motion exceeds: the servo run stops, Python faults it
    same(a, b, od((0x6065, 5)))
    for _ in range(4):
        both(a, b)
    assert a.seg.firmware[0].device.state.name.startswith("FAULT")  # type: ignore[attr-defined]
    same(a, b, od((0x6065, 0xFFFFFFFF)))
    for cw in (0x80, 0x00, 0x06, 0x07, 0x0F, 0x0F):
        both(a, b, cw)
    assert set(codes(answered)) == {REPLIED}, "the mailbox and AL work ran after replies"


def test_responder_with_ecat_events_and_padding() -> None:
    """SM events routed to the ECAT side as well (0x0210 and the IRQ field), and an input
    image with a padding byte, which must be written as 0."""
    a, b = lockstep(1, ecat_irq=True)
    both(a, b)

    def pad(c: CspCycle) -> None:
        app = c.seg.firmware[0].app
        plan = app.plan  # type: ignore[attr-defined]
        tx = list(plan.tx)
        tx[1] = Field(tx[1].offset, tx[1].size, None)  # 6061h display -> padding
        app.plan = replace(plan, tx=tuple(tx), tx_codec=codec(tuple(tx), plan.tx_size))  # type: ignore[attr-defined]
        c.seg.escs[0].mem[0x1200 : 0x1200 + 3 * 17] = b"\xff" * (3 * 17)

    same(a, b, pad)
    for _ in range(8):
        both(a, b)
    assert a.seg.escs[0].ecat_irq != 0


def test_responder_matches_python_on_other_maps(answered: list[tuple[int, int, int]]) -> None:
    """FMMUs beyond the usual pair: a read/write map over SM2 (the master reads its outputs
    back), partial accesses that leave a buffer open across a pulse, a bit-wise map and a
    map onto plain memory. The frames go through the daemon."""
    a, b = lockstep(1)
    for _ in range(3):
        both(a, b)

    def fmmu(n: int, lad: int, length: int, phys: int, typ: int, lsb: int = 0) -> bytes:
        lstop = 7 if lsb == 0 else 6
        return struct.pack("<IHBBHBBB3x", lad, length, lsb, lstop, phys, lsb, typ, 1)

    def frame(*datagrams: bytes) -> Callable[[CspCycle], bytes | None]:
        def go(c: CspCycle) -> bytes | None:
            c.clock.t = c.t + MS // 2
            return c.deliver(dg.ethernet_frame(list(datagrams)))

        return go

    def program(n: int, raw: bytes) -> Callable[[CspCycle], None]:
        def go(c: CspCycle) -> None:
            c.master.apwr(0, 0x0600 + 16 * n, raw)

        return go

    lrd_sm3 = dg.build_logical(dg.Cmd.LRD, 12, bytes(17), more=True)
    # FMMU2: read/write over SM2 at logical 0x8000: a read returns the latest outputs
    same(a, b, program(2, fmmu(2, 0x8000, 12, 0x1100, 3)))
    same(a, b, frame(dg.build_logical(dg.Cmd.LRD, 0x8000, bytes(12))))
    same(a, b, frame(dg.build_logical(dg.Cmd.LWR, 0x8000, bytes(range(4)))))  # opens SM2
    both(a, b)
    same(a, b, frame(dg.build_logical(dg.Cmd.LRW, 0x8004, bytes(range(8)))))  # closes it
    same(a, b, frame(dg.build_logical(dg.Cmd.LRD, 0x8000, bytes(12))))
    # SM3 read in two parts with a pulse between: the firmware writes the third buffer
    same(a, b, frame(dg.build_logical(dg.Cmd.LRD, 12, bytes(1))))
    both(a, b)
    same(a, b, frame(dg.build_logical(dg.Cmd.LRD, 13, bytes(16))))
    assert codes(answered)[-6:] == [REPLIED] * 6
    # a bit-wise map and one onto plain memory (behind an LRD of SM3)
    same(a, b, program(3, fmmu(3, 0x9000, 1, 0x1100, 1, lsb=1)))
    for _ in range(2):
        same(a, b, frame(lrd_sm3, dg.build_logical(dg.Cmd.LRD, 0x9000, bytes(1))))
    same(a, b, program(3, fmmu(3, 0x9000, 4, 0x1800, 3)))
    for _ in range(2):
        same(a, b, frame(lrd_sm3, dg.build_logical(dg.Cmd.LRW, 0x9000, b"\x01\x02\x03\x04")))
    same(a, b, frame(dg.build_logical(dg.Cmd.LRD, 0x9000, bytes(4))))
    assert codes(answered)[-5:] == [REPLIED] * 5
    for _ in range(3):
        both(a, b)


def test_responder_serves_a_reference_behind_an_sm_window(
    answered: list[tuple[int, int, int]],
) -> None:
    """An SM window over the reference's 0x0910 (Esc.ecat_read then goes to the SM): the
    responder's walk is the segment's, and both sides agree."""
    a, b = lockstep(2)
    for _ in range(3):
        both(a, b)
    assert codes(answered)[-1] == REPLIED
    for c in (a, b):
        ref = c.seg.escs[0]
        ref.sm_windows = (*ref.sm_windows, (0x0900, 0x0920, ref.sm[0]))
    both(a, b)
    assert codes(answered)[-1] == REPLIED


def test_responder_serves_every_reference_clock(
    answered: list[tuple[int, int, int]],
) -> None:
    """The FRMW of 0x0910 addressed to each slave of three in turn (the reference's time
    is its arrival time at that slave, plus its offset; the writers before and behind it
    get the master's and the reference's data), to no slave at all (every slave writes),
    and 4 bytes long, each carrying the DC time of the master's last frame: the compiled
    responder and Python agree on replies and state."""
    a, b = lockstep(3)
    for _ in range(3):
        both(a, b)
    lrw = 3 * (OUT + IN)
    dc_time = {False: 0, True: 0}

    def cycle(adp: int, size: int) -> Callable[[CspCycle], bytes | None]:
        def go(c: CspCycle) -> bytes | None:
            c.pulse()  # each frame in a cycle of its own
            c.clock.t = c.t + MS // 2
            raw = bytearray(c.frame(0x0F))
            if size == 4:
                raw = bytearray(
                    dg.ethernet_frame(
                        [
                            dg.build_logical(dg.Cmd.LRW, 0, bytes(raw[26 : 26 + lrw]), more=True),
                            dg.build(dg.Cmd.FRMW, adp, 0x0910, bytes(4)),
                        ]
                    )
                )
            p = 14 + 2 + 10 + lrw + 2  # the FRMW's header
            struct.pack_into("<H", raw, p + 2, adp)
            # what the master sends along, the DC time of its last frame, as SOEM does: the
            # slaves before the reference write it
            raw[p + 10 : p + 10 + size] = dc_time[c.responder].to_bytes(8, "little")[:size]
            reply = c.deliver(bytes(raw))
            assert reply is not None
            dc_time[c.responder] = int.from_bytes(reply[p + 10 : p + 10 + size], "little")
            c.t += MS
            return reply

        return go

    # a new reference makes the slaves before it correct a large difference (their SYNC
    # deadlines move) before it settles
    for adp in (0x1000, 0x1001, 0x1002, 0x7777):
        for size in (8, 4):
            for _ in range(4):
                same(a, b, cycle(adp, size))
    assert codes(answered)[-32:] == [REPLIED] * 32
    both(a, b)


def test_dc_time_loops_wait_for_the_reply() -> None:
    """The FRMW of 0x0910 (the frame's last datagram): the reply carries the reference's
    time and WKC = number of slaves at once; the other slaves' time loops run in
    after_reply(), with the same results as inline (the lockstep test compares those)."""
    a, _b = lockstep(3)
    a.pulse()
    a.clock.t = a.t + MS // 2
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


def test_responder_and_python_agree_on_mutated_frames(answered: list[tuple[int, int, int]]) -> None:
    """Differential fuzz: mutated cyclic frames (truncated, extended, bit flips, broken
    headers and lengths, unknown commands, random tails; a few with changed logical
    addresses so FMMUs are met in part) go through both segments, with SYNC0 pulses
    between them. Replies and every state must agree, and both must still run."""
    rng = random.Random(7)
    a, b = lockstep(2)
    for _ in range(3):
        both(a, b)

    def send(raw: bytes) -> Callable[[CspCycle], bytes | None]:
        def go(c: CspCycle) -> bytes | None:
            c.clock.t = c.t + MS // 2
            return c.deliver(raw)

        return go

    for k in range(300):
        frame = bytearray(a.frame(0x0F))
        if k % 5 == 0:  # shift the LRW's logical address: FMMUs met at their edges
            struct.pack_into("<I", frame, 14 + 2 + 2, rng.randrange(0, 64))
        raw = mutate(rng, bytes(frame)) if k % 5 else bytes(frame)
        same(a, b, send(raw))
        if k % 10 == 9:
            both(a, b)
            a.t += MS
            b.t += MS
    for _ in range(3):
        both(a, b)
    assert a.seg.firmware[0].device.state.name == b.seg.firmware[0].device.state.name  # type: ignore[attr-defined]
    seen = codes(answered)
    assert seen.count(REPLIED) > 100, "the compiled responder answered many of them"
    assert seen.count(DROPPED) > 20, "and destroyed the malformed ones, as Python does"
