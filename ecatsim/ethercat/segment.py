"""A segment: N ESCs cabled port to port. Walks each datagram through them in place.

A frame enters at the daemon's interface (port 0 of the first slave) or at the out
interface (``--out-iface``) and goes through the processing units of the ESCs on its
route (ecatsim/ethercat/topology.py), computed when the cabling, a link or a loop setting
changes. Each slave whose processing unit the frame passes increments ADP for
auto-increment and broadcast commands and adds its working-counter increment.
Ref: ETG.1000.4 §5.3-5.4 (frame and datagram), Table 11 (commands), §5.4.3 (WKC);
TMC8460 §5.35 (processing unit error counter).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from ecatsim.clock import Clock
from ecatsim.esc import regs
from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.regs import DC_SYSTEM_TIME as _DC_SYSTEM_TIME  # compiled: a C constant
from ecatsim.ethercat import topology
from ecatsim.ethercat.logical_index import LogicalIndex
from ecatsim.ethercat.schedule import Schedule, Serviceable
from ecatsim.wire.datagram import (  # compiled: C constants (segment.pxd)
    APRD,
    APRW,
    APWR,
    ARMW,
    BRD,
    BRW,
    BWR,
    CIRCULATING,
    FPRD,
    FPRW,
    FPWR,
    FRMW,
    LEN_MASK,
    LRD,
    LRW,
    LWR,
    MORE_FOLLOWS,
)


class Segment:
    """N slaves in wire order; one call per received frame."""

    #: fixed attributes (the compiled core declares them in segment.pxd)
    __slots__ = (
        "_cur",
        "_cur_exit",
        "_dc_after",
        "_dc_before",
        "_dc_pending",
        "_dc_reach",
        "_dc_reader",
        "_frame",
        "_frame_view",
        "_frmw_adp",
        "_frmw_reader",
        "_frmw_readers",
        "addr_map",
        "bad_frames",
        "chain",
        "clock",
        "compiled",
        "ctx",
        "escs",
        "exit",
        "firmware",
        "frames",
        "irq",
        "logical",
        "logical_index",
        "out_up",
        "port0_closed",
        "processed",
        "reach",
        "reply_first",
        "routes",
        "schedule",
        "wiring",
    )

    def __init__(
        self,
        escs: Sequence[Esc],
        ctx: FrameContext,
        clock: Clock,
        firmware: Sequence[Serviceable] = (),
        persist: Callable[[int], None] | None = None,
        wiring: Sequence[Sequence[int]] | None = None,
        ports: Sequence[int] = (),
    ) -> None:
        """``wiring``: per ESC its ports' cables (ecatsim/ethercat/topology.py; None: a line);
        ``ports``: per ESC the ports it has (bit p; default ports 0 and 1)."""
        self.escs = list(escs)
        self.ctx = ctx
        self.clock = clock
        #: the firmware behind each ESC's PDI, by position
        self.firmware = list(firmware)
        #: the work after the replies: SYNC pulses, timers and that firmware (the same
        #: list), ecatsim/ethercat/schedule.py
        self.schedule = Schedule(self.escs, ctx, self.firmware, persist)
        self.reach = len(self.escs)
        self.addr_map: dict[int, tuple[int, ...]] = {}
        #: the last FRMW's address and the ESCs it names (the reference clock's, the same
        #: every cycle), until the addresses change
        self._frmw_adp = -1
        self._frmw_readers: tuple[int, ...] = ()
        #: the first of them (the reference clock), -1 if none
        self._frmw_reader = -1
        self.logical: list[Esc] = []
        #: the FMMUs of ``logical`` by logical address: a logical datagram reaches only the
        #: ESCs whose FMMUs its range overlaps (decision P99)
        self.logical_index = LogicalIndex()
        #: the daemon's compiled responder may serve this segment's frames (decision P9);
        #: tests compare it with the Python path
        self.compiled = True
        #: the caller sends the reply before it calls after_reply() (the daemon does):
        #: the DC time loops of an FRMW of 0x0910 may wait until then (decision P7)
        self.reply_first = False
        #: an FRMW of 0x0910 whose time loops wait for after_reply(): its data length (0:
        #: none), the reference's position, the reach, and the data the slaves before and
        #: behind the reference saw (no object is made per frame)
        self._dc_pending = 0
        self._dc_reader = 0
        self._dc_reach = 0
        self._dc_before = bytearray(8)
        self._dc_after = bytearray(8)
        #: the buffer of the last frame walked and a view of it, made once per buffer (the
        #: daemon receives every frame into one buffer; the buffer cannot be resized while
        #: the segment holds the view)
        self._frame: bytearray | None = None
        self._frame_view = memoryview(bytearray())
        self.irq = 0
        #: a reachable ESC has its port-0 loop forced closed (circulating-frame handling)
        self.port0_closed = False
        self.frames = 0
        self.bad_frames = 0
        n = len(self.escs)
        #: per ESC the cables of its ports 0-3 (ecatsim/ethercat/topology.py)
        self.wiring = [list(w) for w in wiring] if wiring is not None else topology.linear(n)
        topology.check(self.wiring)
        #: the out interface has carrier (a link at the port cabled to it)
        self.out_up = False
        #: the routes of a frame entering at the daemon's interface (0) and at the out
        #: interface (1, None without one), computed when the topology changes
        self.routes: list[topology.Route | None] = [None, None]
        #: the route whose ESCs the walk serves (chain, reach, addr_map ...): 0 or 1
        self._cur = 0
        self._cur_exit = topology.EXIT_MAIN
        #: the ESCs of that route in processing order (auto-increment positions)
        self.chain: list[Esc] = []
        #: where the last frame leaves (topology.EXIT_MAIN, EXIT_OUT), and whether a
        #: processing unit saw it (only then is its source address marked)
        self.exit = topology.EXIT_MAIN
        self.processed = False
        for i, esc in enumerate(self.escs):
            esc.set_wired(
                topology.wired_mask(self.wiring[i], False), ports[i] if i < len(ports) else 0x3
            )
        self.ctx.topology_dirty = True  # the ESCs may have served another segment object
        self._refresh()

    # ----------------------------------------------------------------- bookkeeping

    def _refresh(self) -> None:
        ctx = self.ctx
        if ctx.topology_dirty:
            ctx.topology_dirty = False
            self._compile()
        if ctx.addr_dirty:
            ctx.addr_dirty = False
            amap: dict[int, list[int]] = {}
            for i in range(self.reach):
                m = self.chain[i].mem
                amap.setdefault(m[regs.STATION_ADDRESS] | (m[regs.STATION_ADDRESS + 1] << 8), [])
                amap[m[regs.STATION_ADDRESS] | (m[regs.STATION_ADDRESS + 1] << 8)].append(i)
                if m[regs.DL_CONTROL + 3] & 0x01:  # 0x0100 bit 24: alias enabled
                    alias = m[regs.STATION_ALIAS] | (m[regs.STATION_ALIAS + 1] << 8)
                    lst = amap.setdefault(alias, [])
                    if i not in lst:
                        lst.append(i)
            self.addr_map = {k: tuple(v) for k, v in amap.items()}
            self._frmw_adp = -1
        if ctx.logical_dirty:
            ctx.logical_dirty = False
            self.logical = [e for e in self.chain if e.fmmus]
            self.logical_index.build(self.logical)
        if ctx.irq_dirty:
            ctx.irq_dirty = False
            irq = 0
            for e in self.chain:
                irq |= e.ecat_irq
            self.irq = irq

    def _compile(self) -> None:
        """The routes from both interfaces, after a change of cabling, link or loop."""
        escs = self.escs
        main = topology.trace(escs, self.wiring, 0, 0) if escs else topology.Route()
        self.routes[0] = main
        out = topology.out_port(self.wiring)
        self.routes[1] = topology.trace(escs, self.wiring, *out) if out is not None else None
        cur = self.routes[self._cur]
        self._use(self._cur if cur is not None and cur.order else 0)

    def _use(self, k: int) -> None:
        """Serve route ``k``: its ESCs in order, and their DC arrival times."""
        route = self.routes[k]
        assert route is not None
        self._cur = k
        self._cur_exit = route.exit
        escs = self.escs
        self.chain = [escs[i] for i in route.order]
        self.reach = len(self.chain)
        self.port0_closed = route.circulating
        for i in route.order:
            dc = escs[i].dc
            dc.arrive_ns = route.unit_ns[i]
            dc.port_ns = route.port_ns[i]
        ctx = self.ctx
        ctx.addr_dirty = ctx.logical_dirty = ctx.irq_dirty = True

    def set_out_link(self, up: bool) -> None:
        """The out interface gained or lost carrier: the port cabled to it has a link or
        not (DL status, loop, lost-link counter follow). Ref: TMC8460 §5.19, §5.38."""
        if up == self.out_up:
            return
        self.out_up = up
        at = topology.out_port(self.wiring)
        if at is None:
            return
        esc = self.escs[at[0]]
        was = esc.ports_link & (1 << at[1])
        esc.wired = topology.wired_mask(self.wiring[at[0]], up)
        m = esc.mem
        loop = (m[regs.DL_CONTROL + 1] >> (2 * at[1])) & 0x03
        a = regs.LOST_LINK_COUNTER + at[1]
        if was and not up and loop == 0 and m[a] < 0xFF:
            m[a] += 1
        esc.update_dl_status()
        self.ctx.topology_dirty = True

    def peer(self, i: int, port: int) -> tuple[int, int] | None:
        """The ESC and port at the other end of ESC ``i``'s ``port`` (None: not a slave)."""
        w = self.wiring[i][port]
        return divmod(w, 4) if w >= 0 else None

    def _stamp(self, route: topology.Route, t_ns: int) -> None:
        """Ports waiting for the frame that now comes in there latch its receive time."""
        escs = self.escs
        waiting = False
        for i, p, off in route.stamps:
            dc = escs[i].dc
            if dc.latch_wait & (1 << p):
                dc.stamp_port(p, t_ns + off)
        for e in escs:
            if e.dc.latch_wait:
                waiting = True
        self.ctx.latch_wait = waiting

    def _count_error(self) -> None:
        """A malformed frame: the first ESC counts it in 0x030C, the ones behind it see a
        frame with a broken FCS and count it in their forwarded RX error counter (port 0).
        Ref: TMC8460 §5.34, §5.35."""
        self.bad_frames += 1
        for i in range(self.reach):
            m = self.chain[i].mem
            a = regs.ECAT_PU_ERROR_COUNTER if i == 0 else regs.FWD_RX_ERROR_COUNTER
            if m[a] < 0xFF:
                m[a] += 1

    # ----------------------------------------------------------------- frame path

    def process(self, buf: bytearray, off: int, n: int, t_ns: int = 0, entry: int = 0) -> bool:
        """Process the EtherCAT frame at ``buf[off:n]`` in place; it arrived at ``t_ns``
        (host monotonic ns; 0: now) at the daemon's interface (``entry`` 0) or the out
        interface (1).

        Returns True if the frame is to be sent on (it may be unmodified; ``exit`` says
        on which interface), False if it is destroyed (malformed, or no route: the
        master sees it as lost).
        Ref: ETG.1000.4 §5.3 (EtherCAT header: length, type), §5.4.
        """
        if self._dc_pending:
            self.after_reply()  # the caller did not: the previous frame's work comes first
        ctx = self.ctx
        ctx.frame_no += 1
        ctx.t_ns = t_ns or self.clock.now_ns()
        self.frames += 1
        if off + 2 > n:
            self._count_error()
            return False
        hdr = buf[off] | (buf[off + 1] << 8)
        if (hdr >> 12) != 1:
            return True  # not a DLPDU frame: forwarded without processing
        end = off + 2 + (hdr & LEN_MASK)
        if end > n:
            self._count_error()
            return False
        # Validate the datagram chain before touching anything.
        p = off + 2
        while True:
            if p + 12 > end:
                self._count_error()
                return False
            lf = buf[p + 6] | (buf[p + 7] << 8)
            q = p + 12 + (lf & LEN_MASK)
            if q > end:
                self._count_error()
                return False
            if not lf & MORE_FOLLOWS:
                break
            p = q
        if ctx.topology_dirty:
            self._refresh()
        if entry != self._cur:
            route = self.routes[entry]
            if route is None or not (route.order or route.exit >= 0):
                return False
            if ctx.latch_wait:
                self._stamp(route, ctx.t_ns)
            if not route.order:  # it passes through unprocessed (back to the master)
                self.exit = route.exit
                self.processed = False
                return True
            self._use(entry)
            self._refresh()
        elif ctx.latch_wait and entry:
            route = self.routes[entry]
            if route is not None:
                self._stamp(route, ctx.t_ns)
        if self.reach == 0:
            return False  # no link at the door: the frame is lost
        self.exit = self._cur_exit
        self.processed = True
        if self.port0_closed and not self._circulate(buf, off + 2):
            return False
        self._walk(buf, off + 2)
        return self._cur_exit >= 0  # EXIT_LOST: destroyed after the processing units

    def _frmw_system_time(self, data: memoryview, first: int, reach: int) -> int:
        """The DC time distribution (FRMW of 0x0910, the frame's last datagram) with the
        writers' time loops after the reply (decision P7): the reference's read is all the
        reply needs, and a register write always counts (+1 per writer). The writes run
        in :meth:`after_reply` with this frame's time stamp, so their results are the
        same as inline; no later datagram of this frame can see the difference. The data
        the writers before and behind the reference see is kept in two preallocated
        buffers. ``first``: the ESC the address names (the reference clock), -1 if none.
        Ref: ETG.1000.4 Table 12 (FRMW); TMC8460 §5.50.2 Table 95."""
        reader = first if first >= 0 else reach  # no reader: every slave writes
        n = len(data)
        if reader > 0:
            before = self._dc_before
            before[:n] = data
        inc = 0
        if reader < reach:
            esc = self.chain[reader]
            inc += esc.ecat_read_system_time(data)
        if reader + 1 < reach:
            after = self._dc_after
            after[:n] = data
        self._dc_pending = n
        self._dc_reader = reader
        self._dc_reach = reach
        return inc + reach - (1 if reader < reach else 0)

    def after_reply(self) -> None:
        """Work a frame left for after its reply: the writers' DC time loops (P7)."""
        n = self._dc_pending
        if not n:
            return
        self._dc_pending = 0
        reader = self._dc_reader
        reach = self._dc_reach
        escs = self.chain
        if reader > 0:  # the writers before the reference (all of them, if none reads)
            before = bytes(self._dc_before[:n])
            for i in range(min(reader, reach)):
                esc = escs[i]
                esc.ecat_write_system_time(before)  # ecat_write of 0x0910 (P26)
        if reader + 1 < reach:  # the writers behind it
            after = bytes(self._dc_after[:n])
            for i in range(reader + 1, reach):
                esc = escs[i]
                esc.ecat_write_system_time(after)  # ecat_write of 0x0910 (P26)

    def _circulate(self, buf: bytearray, p: int) -> bool:
        """A frame passing an ESC whose port 0 is closed gets the circulating bit; one that
        already has it is destroyed, so a frame cannot circle forever.
        Ref: ETG.1000.4 §5.4 (C bit); TMC8460 §5.17 (loop port 0)."""
        if buf[p + 7] & (CIRCULATING >> 8):
            self.bad_frames += 1
            return False
        while True:
            buf[p + 7] |= CIRCULATING >> 8
            lf = buf[p + 6] | (buf[p + 7] << 8)
            if not lf & MORE_FOLLOWS:
                return True
            p += 12 + (lf & LEN_MASK)

    def _walk(self, buf: bytearray, p: int) -> None:
        if buf is not self._frame:
            self._frame_view = memoryview(buf)
            self._frame = buf
        mv = self._frame_view
        ctx = self.ctx
        escs = self.chain
        while True:
            if ctx.topology_dirty or ctx.addr_dirty or ctx.logical_dirty or ctx.irq_dirty:
                self._refresh()
            reach = self.reach
            cmd = buf[p]
            lf = buf[p + 6] | (buf[p + 7] << 8)
            dlen = lf & LEN_MASK
            d0 = p + 10
            w = d0 + dlen
            data = mv[d0:w]
            inc = 0
            adp = buf[p + 2] | (buf[p + 3] << 8)
            ado = buf[p + 4] | (buf[p + 5] << 8)
            if cmd in (LRW, LRD, LWR):
                # C calls, pointers into buf (P61), to the ESCs the range reaches (P99)
                inc += self.logical_index.walk(cmd, adp | (ado << 16), buf, d0, dlen)
            elif cmd in (FPRD, FPWR, FPRW):
                for i in self.addr_map.get(adp, ()):
                    inc += _physical(escs[i], cmd - FPRD, ado, data)
            elif cmd in (APRD, APWR, APRW):
                k = (-adp) & 0xFFFF
                if k < reach:
                    inc += _physical(escs[k], cmd - APRD, ado, data)
            elif cmd == BRD:
                for i in range(reach):
                    inc += escs[i].ecat_read_or(ado, data)
            elif cmd == BWR:
                src = bytes(data)  # once per datagram: every slave writes the same bytes
                for i in range(reach):
                    inc += escs[i].ecat_write(ado, src)
            elif cmd == BRW:
                for i in range(reach):
                    incoming = bytes(data)
                    inc += escs[i].ecat_read_or(ado, data)
                    inc += 2 * escs[i].ecat_write(ado, incoming)
            elif cmd == ARMW:
                k = (-adp) & 0xFFFF
                for i in range(reach):
                    if i == k:
                        inc += escs[i].ecat_read(ado, data)
                    else:
                        inc += escs[i].ecat_write(ado, data)
            elif cmd == FRMW:
                if adp != self._frmw_adp:
                    self._frmw_readers = self.addr_map.get(adp, ())
                    self._frmw_reader = self._frmw_readers[0] if self._frmw_readers else -1
                    self._frmw_adp = adp
                readers = self._frmw_readers
                if (
                    self.reply_first
                    and ado == _DC_SYSTEM_TIME
                    and not lf & MORE_FOLLOWS
                    and len(readers) <= 1
                    and dlen in (4, 8)
                ):
                    inc += self._frmw_system_time(data, self._frmw_reader, reach)
                else:
                    for i in range(reach):
                        if i in readers:
                            inc += escs[i].ecat_read(ado, data)
                        else:
                            inc += escs[i].ecat_write(ado, data)
            if APRD <= cmd <= APRW or BRD <= cmd <= BRW or cmd == ARMW:
                # position addressing: each slave on the route counts ADP up by one
                # (ETG.1000.4 §5.4.1, Table 11)
                adp = (adp + reach) & 0xFFFF
                buf[p + 2] = adp & 0xFF
                buf[p + 3] = adp >> 8
            # NOP and unknown commands: no slave acts on them.
            if cmd:
                irq = self.irq
                if irq:
                    buf[p + 8] |= irq & 0xFF
                    buf[p + 9] |= irq >> 8
                if inc:
                    wkc = (buf[w] | (buf[w + 1] << 8)) + inc
                    buf[w] = wkc & 0xFF
                    buf[w + 1] = (wkc >> 8) & 0xFF
            if not lf & MORE_FOLLOWS:
                return
            p = w + 2

    # ----------------------------------------------------------------- after the reply

    def service(self, now_ns: int | None = None) -> None:
        """The work after the replies due by ``now_ns`` (None: now): the DC time loops a
        frame left (P7), then the schedule's pulses, timers and firmware. Never called
        between receive and reply."""
        self.service_at(self.clock.now_ns() if now_ns is None else now_ns)

    def service_at(self, t: int) -> None:
        """:meth:`service` at host time ``t`` (the compiled responder's call: a C integer)."""
        if self._dc_pending:
            self.after_reply()
        self.schedule.service_at(t)


def _physical(esc: Esc, op: int, ado: int, data: memoryview) -> int:
    """op 0 read, 1 write, 2 read/write (+1 read, +2 write). Ref: ETG.1000.4 Table 12."""
    if op == 0:
        return esc.ecat_read(ado, data)
    if op == 1:
        return esc.ecat_write(ado, data)
    incoming = memoryview(bytes(data))
    return esc.ecat_read(ado, data) + 2 * esc.ecat_write(ado, incoming)
