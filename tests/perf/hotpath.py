"""Hot-path micro-benchmark shared by the regression test and ``tools/microbench.py``.

Costs are reported as a ratio to a calibration loop run in the same process, so the
stored baseline moves less with the machine than absolute times do.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable
from typing import Any

from ecatsim.ethercat.daemon import Daemon
from ecatsim.link.loopback import LoopbackLink
from ecatsim.wire import datagram as dg
from ecatsim.wire.frame import ecat_offset, mark_processed
from tests.support.socketlink import SocketLink
from tests.support.tinymaster import TinyMaster, segment_of


def calibrate(n: int = 200_000) -> float:
    """Seconds per iteration of a fixed pure-Python loop (the unit of the ratios)."""
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        acc = 0
        buf = bytearray(64)
        for i in range(n):
            acc += buf[i & 63] | (i & 0xFF)
            buf[i & 63] = acc & 0xFF
        best = min(best, time.perf_counter() - t)
    return best / n


def configure_to_op(m: TinyMaster, n_slaves: int, ecat_irq: bool = False) -> None:
    """Bring a segment to OP the way SOEM does: slaves to defaults (loops auto, alias off,
    error counters, EEPROM to EtherCAT), INIT, clear FMMUs/SMs, addresses, mailbox SMs,
    PREOP, process-data SMs and FMMUs, SAFEOP, a cycle, OP. ``ecat_irq``: the process-data SMs
    also raise ECAT events, and the ECAT event mask lets every event through."""
    m.bwr(0x0101, b"\x00")  # DL control: auto loop on every port
    m.bwr(0x0103, b"\x00")  # alias off
    m.bwr(0x0200, b"\xff\xff" if ecat_irq else b"\x00\x00")  # ECAT event mask
    m.bwr(0x0300, bytes(8))  # error counters
    m.bwr(0x0981, b"\x00")  # SYNC activation off
    m.bwr(0x0500, b"\x02")  # EEPROM: force EtherCAT ...
    m.bwr(0x0500, b"\x00")  # ... and release
    m.bwr(0x0120, b"\x11\x00")
    m.bwr(0x0600, bytes(16 * 6))
    m.bwr(0x0800, bytes(8 * 6))
    for pos in range(n_slaves):
        m.apwr(pos, 0x0010, struct.pack("<H", 0x1000 + pos))
        m.apwr(pos, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
        m.apwr(pos, 0x0808, struct.pack("<HHBBBB", 0x1080, 128, 0x22, 0, 1, 0))
        m.apwr(pos, 0x0120, b"\x02\x00")
        irq = 0x10 if ecat_irq else 0x00
        m.apwr(pos, 0x0810, struct.pack("<HHBBBB", 0x1100, 12, 0x64 | irq, 0, 1, 0))
        m.apwr(pos, 0x0818, struct.pack("<HHBBBB", 0x1200, 17, 0x20 | irq, 0, 1, 0))
        out_lad = pos * 12
        in_lad = n_slaves * 12 + pos * 17
        m.apwr(pos, 0x0600, struct.pack("<IHBBHBBB3x", out_lad, 12, 0, 7, 0x1100, 0, 2, 1))
        m.apwr(pos, 0x0610, struct.pack("<IHBBHBBB3x", in_lad, 17, 0, 7, 0x1200, 0, 1, 1))
        m.apwr(pos, 0x0120, b"\x04\x00")
    m.lrw(0, bytes(n_slaves * 29))  # a first cycle: SAFEOP -> OP waits for outputs (F5)
    for pos in range(n_slaves):
        m.apwr(pos, 0x0120, b"\x08\x00")


def op_segment(n_slaves: int) -> tuple[TinyMaster, bytearray, int]:
    """A segment in OP as SOEM leaves it, plus the cyclic LRW frame."""
    seg, _ = segment_of(n_slaves)
    m = TinyMaster(seg)
    configure_to_op(m, n_slaves)
    size = n_slaves * 29
    frame = bytearray(
        dg.ethernet_frame(
            [
                dg.build_logical(dg.Cmd.LRW, 0, bytes(size), more=True),
                dg.build(dg.Cmd.FPRD, 0x1000, 0x0130, bytes(2)),
            ]
        )
    )
    return m, frame, len(frame)


def frame_cost(n_slaves: int, iterations: int = 2000) -> float:
    """Seconds per cyclic frame (process + reply patch + service), best of three runs."""
    m, template, n = op_segment(n_slaves)
    seg = m.seg
    buf = bytearray(template)
    off = ecat_offset(buf, n, True)
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(iterations):
            buf[:] = template
            seg.process(buf, off, n)
            mark_processed(buf)
            seg.service()
        best = min(best, time.perf_counter() - t)
    return best / iterations


MS = 1_000_000
OUT, IN = 12, 17  # TMC8670 default PDOs (config/tmc8670.yaml)
CSP = 8
#: the most process data one LRW carries in a frame of 1514 bytes (Ethernet header, EtherCAT
#: header, datagram header and WKC off), and what the first frame gives up for the FRMW of
#: the DC system time behind its LRW (a datagram header, 8 bytes, a WKC). ETG.1000.4 §5.2;
#: SOEM's EC_MAXLRWDATA and EC_FIRSTDCDATAGRAM.
MAX_LRW = 1486
FRMW_BYTES = 20


def segments(n: int) -> list[tuple[int, int]]:
    """The cyclic LRWs' byte ranges of the process image of ``n`` drives (the outputs of
    every drive, then the inputs): each frame as full as it goes, cut between two drives'
    blocks, the first leaving room for the FRMW, as SOEM's config_map segments its IO map."""
    cuts = [k * OUT for k in range(1, n + 1)] + [n * OUT + k * IN for k in range(1, n + 1)]
    out: list[tuple[int, int]] = []
    start = prev = 0
    room = MAX_LRW - FRMW_BYTES
    for c in cuts:
        if c - start > room:
            out.append((start, prev))
            start, room = prev, MAX_LRW
        prev = c
    out.append((start, prev))
    return out


class CspCycle:
    """N drives in OP, enabled in csp, SYNC0 at 1 ms; ``step()`` runs one cycle: the pulse,
    then the cycle's frames (:meth:`frames`) mid-cycle."""

    def __init__(
        self,
        drives: int,
        device: str = "tmc8670",
        enable: bool = True,
        compiled: bool = True,
        ecat_irq: bool = False,
        responder: bool = False,
        clock: Any = None,
        amplitude: int = 20_000,
        frame_waiting: Callable[[], bool] | None = None,
    ) -> None:
        """``amplitude``: the targets follow a cosine of this many counts from the first
        enabled cycle on (0: the drives hold the position they were enabled at, never
        moved, as SOEM's red_test leaves them). ``frame_waiting``: the schedule's look for
        a waiting frame from power-up on, as on the daemon's link (decision P30)."""
        self.n = drives
        #: frames go through the compiled responder (decision P9) over a socket pair
        self.responder = responder
        #: ``clock``: the segment's clock (default: a manual clock the cycles move)
        self.seg, self.clock = segment_of(drives, device=device, clock=clock)
        self.seg.schedule.frame_waiting = frame_waiting
        #: the LRWs' byte ranges of the process image, and the FRMW behind the first
        self.cuts = segments(drives)
        self.frmw = dg.build(dg.Cmd.FRMW, 0x1000, 0x0910, bytes(8))
        self.seg.compiled = compiled  # the responder may serve the segment (decision P9)
        t = self.master = TinyMaster(self.seg)
        configure_to_op(t, drives, ecat_irq)
        self.link: LoopbackLink | SocketLink = SocketLink() if responder else LoopbackLink()
        self.daemon = Daemon(self.link, self.seg)
        self.seg.reply_first = compiled  # the reference runs the DC time loops inline
        self.buf = bytearray(2048)
        for fw in self.seg.firmware:
            coe = getattr(fw, "coe", None)
            if coe is not None:
                coe.od.set(0x6060, 0, CSP)
        ref = struct.unpack("<Q", t.aprd(0, 0x0910, 8).data)[0]
        start = ref + 2 * MS
        for pos in range(drives):  # system time offsets as SOEM's config_dc writes them
            local = struct.unpack("<Q", t.aprd(pos, 0x0910, 8).data)[0]
            t.apwr(pos, 0x0920, struct.pack("<Q", (ref - local) & (2**64 - 1)))
            t.apwr(pos, 0x09A0, struct.pack("<I", MS))
            t.apwr(pos, 0x0990, struct.pack("<Q", start))
            t.apwr(pos, 0x0981, b"\x03")
        t0 = self.seg.escs[0].dc.sync0_deadline()
        assert t0 is not None
        self.t = t0
        self.k = 0
        self.target = 0
        self.amplitude = amplitude
        self.cw = 0x0F if enable else 0x00
        for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F) if enable else ():
            self.step(cw)  # shutdown, switch on, enable operation

    def frame(self, cw: int) -> bytes:
        """The cycle's first frame (the only one up to 50 drives): see :meth:`frames`."""
        return self.frames(cw)[0]

    def frames(self, cw: int) -> list[bytes]:
        """The cycle's frames as a master sends them: the process image in LRWs of at most
        :data:`MAX_LRW` bytes (:func:`segments`), the FRMW of the DC system time in the
        first frame behind its LRW."""
        # every drive gets the same outputs: one copy repeated (the master's side of the
        # cycle stays a few C calls, outside the daemon's measured cost)
        image = struct.pack("<HiHi", cw, self.target, 0, 0) * self.n + bytes(IN * self.n)
        (a, b), *rest = self.cuts
        out = [
            dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, a, image[a:b], more=True), self.frmw])
        ]
        for a, b in rest:
            out.append(dg.ethernet_frame([dg.build_logical(dg.Cmd.LRW, a, image[a:b])]))
        return out

    def step(self, cw: int | None = None) -> bytes:
        self.pulse()
        return self.exchange(cw)

    def pulse(self) -> None:
        """The SYNC0 pulse of this cycle, served by the daemon's timers."""
        self.clock.t = self.t + 20_000  # the timer wakes a little late, as poll(2) does
        self.daemon._service_timers()

    def exchange(self, cw: int | None = None) -> bytes:
        """The cycle's frames, mid-cycle, one after the other's reply; returns the replies,
        joined (one frame up to 50 drives)."""
        self.clock.t = self.t + MS // 2
        self.target = int(self.amplitude * (1 - math.cos(self.k * 2e-3 * math.pi)))
        replies = []
        for f in self.frames(self.cw if cw is None else cw):
            reply = self.deliver(f)
            assert reply is not None
            replies.append(reply)
        self.t += MS
        self.k += 1
        return b"".join(replies)

    def deliver(self, raw: bytes) -> bytes | None:
        """One frame through the daemon, arriving now; its reply (None: none)."""
        self.link.master_send(raw)
        if self.responder:
            self.daemon.serve_once(self.buf, 0, self.clock.t)
        else:
            self.link.rx_ns = self.clock.t
            self.daemon.handle_one(self.buf)
        reply = self.link.master_recv()
        return None if reply is None else bytes(reply)


def csp_cycle_cost(drives: int, cycles: int = 300, responder: bool = False) -> float:
    """Seconds per DC cycle (SYNC0 pulse + cyclic frame) with enabled drives in csp, best
    of three runs; ``responder``: the frame through the compiled responder (P9) over a
    socket pair."""
    c = CspCycle(drives, responder=responder)
    for _ in range(50):
        c.step()
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(cycles):
            c.step()
        best = min(best, time.perf_counter() - t)
    return best / cycles
