"""The emulated TMC8460 EtherCAT Slave Controller: memory, access rules and side effects.

ECAT face: ``ecat_read``/``ecat_read_or``/``ecat_write`` patch a datagram's data in place and return
the slave's working-counter increment; logical datagrams go through ``ecatsim.esc.fmmu.logical_at``
(the FMMUs, then ``_fmmu_xfer`` or the SM's own calls). PDI face: see ``ecatsim.esc.pdi``. Access
rights, reset values and side effects come from the register table
(``ecatsim/spec/registers.yaml``); a row's ``side_effect: <unit>.<name>`` names the hooks of one of
the ESC's units (``Esc.units``: the ESC itself, its DC, MII, EEPROM and watchdog units and its
SyncManagers), methods of that unit's class named ``_ew_<name>``, ``_ec_<name>``, ``_er_<name>``,
``_pw_<name>``, ``_pr_<name>`` (ecatsim/esc/dispatch.py).

Ref: TMC8460 §4, §5; ETG.1000.4 §6 (DL services and ESC memory).
"""

from __future__ import annotations

from collections.abc import Callable
from operator import itemgetter

from ecatsim.esc.context import FrameContext
from ecatsim.esc.dc import DcUnit
from ecatsim.esc.eeprom import EepromUnit
from ecatsim.esc.fmmu import FmmuMap, compile_fmmus, copy_bits
from ecatsim.esc.mii import MiiUnit
from ecatsim.esc.regs import (
    AL_EVENT_MASK,
    AL_EVENT_REQUEST,
    AL_STATUS,
    DC_ECAT_EVENT_TIME,
    DC_PDI_CHANGE_EVENT_TIME,
    DC_PDI_START_EVENT_TIME,
    DC_SYNC0_STATUS,
    DC_SYNC1_STATUS,
    DC_SYSTEM_TIME,
    DL_CONTROL,
    DL_STATUS,
    ECAT_EV_AL_STATUS,
    ECAT_EV_DL_STATUS,
    ECAT_EV_SM0,
    ECAT_EVENT_MASK,
    ECAT_EVENT_REQUEST,
    ECAT_PU_ERROR_COUNTER,
    ESC_CONFIG,
    EV_AL_CONTROL,
    EV_SM0,
    EV_SM_ACTIVATION,
    EV_SYNC0,
    EV_SYNC1,
    EV_WATCHDOG_PD,
    LOST_LINK_COUNTER,
    N_SM,
    PDI_ERROR_CODE,
    PDI_ERROR_COUNTER,
    PDRAM_END,
    PDRAM_START,
    REGISTER_END,
    RX_ERROR_COUNTER,
    SM_ACT_ENABLE,
    SM_ACT_LATCH_ECAT,
    SM_ACT_LATCH_PDI,
    SM_BASE,
    SM_STRIDE,
    WD_COUNTER_PDI,
    WD_STATUS_PD,
)
from ecatsim.esc.sm import SmHost, SyncManager
from ecatsim.esc.watchdog import Watchdog


def _get32(m: bytes | bytearray, a: int) -> int:
    """The little-endian 32-bit register at ``a`` (registers only: decision P27)."""
    p = m  # compiled: a C pointer to the bytes, no index checks
    b3 = p[a + 3]  # compiled: a 64-bit integer, so bit 31 does not sign-extend
    return p[a] | (p[a + 1] << 8) | (p[a + 2] << 16) | (b3 << 24)


def _first(hooked: bytes, s: int, e: int) -> int:
    """The first address in [s, e) whose register has a side effect (-1: none)."""
    p = hooked  # compiled: a C pointer, the loop bounded by the table's length
    for i in range(s, min(e, len(hooked))):
        if p[i]:
            return i
    return -1


def _put16(m: bytearray, a: int, v: int) -> None:
    p = m  # compiled: a pointer, as in _get32 (registers only)
    p[a] = v & 0xFF
    p[a + 1] = (v >> 8) & 0xFF


def _put32(m: bytearray, a: int, v: int) -> None:
    p = m  # compiled: a pointer, as in _get32 (registers only)
    p[a] = v & 0xFF
    p[a + 1] = (v >> 8) & 0xFF
    p[a + 2] = (v >> 16) & 0xFF
    p[a + 3] = (v >> 24) & 0xFF


class Esc(SmHost):
    """One TMC8460 ESC instance (64 KiB address space, 6 FMMUs, 6 SMs)."""

    #: fixed attributes (compiled: the typed fields of core.pxd)
    __slots__ = (
        "_scratch",
        "_scratch_view",
        "al_control_locked",
        "ctx",
        "dc",
        "ecat_irq",
        "ecat_r_hooked",
        "ecat_r_hooks",
        "ecat_w_change",
        "ecat_w_hooked",
        "ecat_w_hooks",
        "ecat_wmask",
        "eeprom",
        "fmmus",
        "irq_line",
        "link_down",
        "mem",
        "memv",
        "mii",
        "mp",
        "on_reset",
        "pdi_emulation",
        "pdi_r_hooked",
        "pdi_r_hooks",
        "pdi_w_hooked",
        "pdi_w_hooks",
        "pdi_wmask",
        "pdram_ok",
        "port0_closed",
        "port0_open",
        "port1_closed",
        "ports",
        "ports_link",
        "ports_open",
        "position",
        "reset_progress_frame",
        "sm",
        "sm_windows",
        "t",
        "units",
        "wd",
        "wired",
        "wr_e",
        "wr_s",
    )

    def __init__(
        self,
        position: int,
        ctx: FrameContext,
        sii: bytearray,
        *,
        dc_start_ns: int = 0,
        dc_drift_ppm: float = 0.0,
        dc_hop_ns: int = 500,
        pdi_emulation: bool = False,
    ) -> None:
        self.position = position
        #: the PDI_EMULATION pin: 0x0141 bit 0 until the EEPROM's word 0 is loaded (§5.26)
        self.pdi_emulation = pdi_emulation
        self.ctx = ctx
        self.mem = bytearray(0x10000)
        #: a view of mem for the read paths (mem is never resized or replaced)
        self.memv = memoryview(self.mem)
        self.mp = self.mem  # compiled: a pointer to its bytes (fixed: memv holds them), P62
        from ecatsim.esc.units import tables  # the table names this class: built at first use

        t = self.t = tables()
        #: the tables' masks and side-effect bitmaps, bound here (typed in the compiled core)
        self.ecat_wmask = t.ecat_wmask
        self.pdi_wmask = t.pdi_wmask
        self.ecat_w_hooked = t.ecat_w_hooked
        self.ecat_w_change = t.ecat_w_change
        self.pdi_w_hooked = t.pdi_w_hooked
        self.ecat_r_hooked = t.ecat_r_hooked
        self.pdi_r_hooked = t.pdi_r_hooked
        self.ecat_w_hooks = t.ecat_w
        self.pdi_w_hooks = t.pdi_w
        self.ecat_r_hooks = t.ecat_r
        self.pdi_r_hooks = t.pdi_r
        self.sm = [SyncManager(self, n) for n in range(N_SM)]
        self.eeprom = EepromUnit(self, sii, self._eeprom_written)
        self.dc = DcUnit(
            self, position, start_ns=dc_start_ns, drift_ppm=dc_drift_ppm, hop_ns=dc_hop_ns
        )
        self.wd = Watchdog(self)
        self.mii = MiiUnit(self)
        #: the units whose hooks the register table names, at the slots of
        #: ecatsim/esc/dispatch.py (SLOTS): the side-effect bitmaps hold slot + 1
        self.units = (self, self.dc, self.mii, self.eeprom, self.wd, *self.sm)
        self.fmmus: tuple[FmmuMap, ...] = ()
        self.sm_windows: tuple[tuple[int, int, SyncManager], ...] = ()
        self.pdram_ok = False
        #: the ports that exist (bit p): 0 and 1 on the TMC8460; a junction has 2 and 3 too
        self.ports = 0x3
        #: the ports with a cable to a slave or an interface (bit p), set by the segment
        self.wired = 0x1
        #: the ports with a link (bit p) and the open ones (loop control and link), kept by
        #: update_dl_status for the segment's routes (ecatsim/ethercat/topology.py)
        self.ports_link = 0x1
        self.ports_open = 0x1
        #: port 0 closed by its loop setting or a lost link (the circulating-frame check)
        self.port0_closed = False
        self.port1_closed = True
        self.port0_open = True
        #: injected link faults per port (0-3)
        self.link_down = [False, False, False, False]
        self.al_control_locked = False
        self.reset_progress_frame = -1
        self.ecat_irq = 0
        #: the PDI interrupt line (IRQ pin), as last set by _pdi_irq: this ESC's position
        #: is raised in ctx (ctx.pending) while it is high
        self.irq_line = False
        #: byte range [wr_s, wr_e) of the register write being processed (for hooks)
        self.wr_s = 0
        self.wr_e = 0
        self._scratch = bytearray(2048)
        self._scratch_view = memoryview(self._scratch)
        #: called after a hardware reset ('RES' sequence or power cycle); set by the slave
        self.on_reset: Callable[[], None] | None = None
        self.power_on()

    # ================================================================ reset / load

    def power_on(self) -> None:
        """Power-on reset: registers to reset values, SMs/FMMUs off, EEPROM loaded.

        Ref: TMC8460 §5 reset value columns; §5.45 (EEPROM loaded after reset).
        """
        m = self.mem
        m[:] = bytes(0x10000)
        for addr, size, value in self.t.resets:
            m[addr : addr + size] = value.to_bytes(size, "little")
        m[ESC_CONFIG] = (m[ESC_CONFIG] & 0xFE) | int(self.pdi_emulation)
        m[DL_STATUS] |= 0x04  # enhanced link detection: 1 until the first EEPROM load
        for s in self.sm:
            s.configure(0, 0, 0, False)
        self.fmmus = ()
        self.sm_windows = ()
        self.al_control_locked = False
        self.dc.reset_sync()
        self.ctx.timers_dirty = True
        self.wd.deadline_ns = 0
        self.wd.reconfigure()
        m[WD_STATUS_PD] &= 0xFE  # "expired" until first triggered (reset value 0)
        self.mii.reset()
        self.pdram_ok = self.eeprom.load(first=True)
        if self.pdram_ok:
            m[DL_STATUS] |= 0x02  # PDI watchdog reloaded: the firmware is running
        self.update_dl_status()
        self.ctx.addr_dirty = self.ctx.logical_dirty = self.ctx.irq_dirty = True
        self.ctx.topology_dirty = True
        self.ctx.set_raised(self.position, False)
        self.irq_line = False
        self.ecat_irq = 0

    def _eeprom_written(self) -> None:
        self.ctx.flush.add(self.position)

    # ================================================================ topology

    def set_wired(self, wired: int, ports: int = 0x3) -> None:
        """Record which ports (bit p) have a cable (to a slave or an interface with
        carrier) and which ports exist."""
        self.wired = wired
        self.ports = ports | 0x3
        self.update_dl_status()

    def update_dl_status(self) -> None:
        """Compute 0x0110:0x0111 from links and the loop settings in 0x0100.

        A port has a link if it exists, has a cable and no fault took the link down. Loop
        setting per port (2 bits of 0x0101): 0 auto and 1 auto-close (closed without a
        link), 2 always open, 3 always closed. Ports that do not exist (2 and 3 on the
        TMC8460) are closed with no communication.
        Ref: TMC8460 §5.19 Tables 30, 31; §5.17 Table 28 bits 8-15.
        """
        m = self.mem
        loop = m[DL_CONTROL + 1]
        lo = m[DL_STATUS] & 0x07
        hi = 0
        links = 0
        opened = 0
        for p in range(4):
            bit = 1 << p
            link = bool(self.ports & bit and self.wired & bit) and not self.link_down[p]
            setting = (loop >> (2 * p)) & 0x03
            absent = not self.ports & bit
            closed = absent or setting == 0x03 or (setting != 0x02 and not link)
            if link:
                links |= bit
                lo |= 0x10 << p
            if closed:
                hi |= 0x01 << (2 * p)
            else:
                opened |= bit
                if link:
                    hi |= 0x02 << (2 * p)
        self.ports_link = links
        self.ports_open = opened
        self.port0_open = bool(links & 0x1)  # no link: no frame enters at port 0
        self.port0_closed = not opened & 0x1
        self.port1_closed = not opened & 0x2
        old = m[DL_STATUS] | (m[DL_STATUS + 1] << 8)
        m[DL_STATUS] = lo
        m[DL_STATUS + 1] = hi
        self.mii.set_link(0, bool(links & 0x1))
        self.mii.set_link(1, bool(links & 0x2))
        if old != (lo | (hi << 8)):
            self._set_ecat_event(ECAT_EV_DL_STATUS)
            self.ctx.topology_dirty = True

    def set_pdi_watchdog(self, alive: bool) -> None:
        """The PDI watchdog: 0x0110 bit 1 (1 = reloaded, 0 = expired), each expiry counted
        in 0x0443, the change signalled as a DL status event. Ref: TMC8460 §5.19 Table 30,
        §5.40, §5.44."""
        m = self.mem
        if bool(m[DL_STATUS] & 0x02) == alive:
            return
        if alive:
            m[DL_STATUS] |= 0x02
        else:
            m[DL_STATUS] &= 0xFD
            if m[WD_COUNTER_PDI] < 0xFF:
                m[WD_COUNTER_PDI] += 1
        self.update_dl_status()
        self._set_ecat_event(ECAT_EV_DL_STATUS)

    def pdi_interface_error(self, code: int) -> None:
        """A PDI access with an interface error: 0x030D counts (saturating at 0xFF), 0x030E
        keeps the code of the last one. Ref: TMC8460 §5.36 Table 50, §5.37 Table 51."""
        m = self.mem
        if m[PDI_ERROR_COUNTER] < 0xFF:
            m[PDI_ERROR_COUNTER] += 1
        m[PDI_ERROR_CODE] = code & 0xFF

    def set_link(self, port: int, up: bool) -> None:
        """A link fault on a port (0-3): DL status changes; a lost link at an open port
        in Auto loop mode counts in 0x0310+port. Ref: TMC8460 §5.19, §5.38 Table 52."""
        if self.link_down[port] == (not up):
            return
        self.link_down[port] = not up
        m = self.mem
        loop = (m[DL_CONTROL + 1] >> (2 * port)) & 0x03
        if not up and loop == 0 and m[LOST_LINK_COUNTER + port] < 0xFF:
            m[LOST_LINK_COUNTER + port] += 1
        self.update_dl_status()
        self.ctx.topology_dirty = True

    # ================================================================ events

    def _set_ecat_event(self, bits: int) -> None:
        m = self.mp
        v = m[ECAT_EVENT_REQUEST] | (m[ECAT_EVENT_REQUEST + 1] << 8)
        if (v | bits) != v:
            _put16(m, ECAT_EVENT_REQUEST, v | bits)
            self._irq_update()

    def _clr_ecat_event(self, bits: int) -> None:
        m = self.mp
        v = m[ECAT_EVENT_REQUEST] | (m[ECAT_EVENT_REQUEST + 1] << 8)
        if v & bits:
            _put16(m, ECAT_EVENT_REQUEST, v & ~bits)
            self._irq_update()

    def _irq_update(self) -> None:
        """IRQ field contribution: ECAT event request AND ECAT event mask. Ref: §5.29, 5.31."""
        m = self.mp
        req = m[ECAT_EVENT_REQUEST] | (m[ECAT_EVENT_REQUEST + 1] << 8)
        mask = m[ECAT_EVENT_MASK] | (m[ECAT_EVENT_MASK + 1] << 8)
        irq = req & mask
        if irq != self.ecat_irq:
            self.ecat_irq = irq
            self.ctx.irq_dirty = True

    def al_event(self) -> int:
        return _get32(self.mem, AL_EVENT_REQUEST)

    def set_al_event(self, bits: int) -> None:
        """Raise AL event request bits (the PDI interrupt source). Ref: §5.32 Table 46."""
        self._al_request(_get32(self.mp, AL_EVENT_REQUEST) | bits)

    def clr_al_event(self, bits: int) -> None:
        v = _get32(self.mp, AL_EVENT_REQUEST)
        if v & bits:
            self._al_request(v & ~bits)

    def _al_request(self, v: int) -> None:
        """0x0220 := ``v`` and the PDI interrupt (inline in the event paths, P62)."""
        _put32(self.mp, AL_EVENT_REQUEST, v)
        self._pdi_irq(v)

    def _pdi_irq(self, request: int) -> None:
        """The PDI interrupt: AL event request AND AL event mask. Ref: §5.32, §5.33. The
        context's record changes only where the line does (most changes leave it high)."""
        line = (request & _get32(self.mp, AL_EVENT_MASK)) != 0
        if line == self.irq_line:
            return
        self.irq_line = line
        self.ctx.set_raised(self.position, line)

    def memory(self) -> bytearray:
        return self.mem

    def sm_status_changed(self, sm: SyncManager) -> None:
        """Mirror an SM's interrupt bits (``sm.mirror``, bit 0 ECAT, bit 1 PDI) into 0x0210
        bit 4+n and 0x0220 bit 8+n. The SM calls this only when they change (only SM
        accesses change these bits). Ref: §5.49 Tables 88, 89."""
        self._sm_events(sm.mirror, sm.n, sm.changed)

    def _sm_events(self, mirror: int, n: int, changed: int) -> None:
        """sm_status_changed's work, inline (an override in a final type cannot type its
        locals, P17, P62): only the bits that ``changed`` are set or cleared (P29)."""
        if changed & 1 and mirror & 1:
            self._set_ecat_event(ECAT_EV_SM0 << n)
        elif changed & 1:
            self._clr_ecat_event(ECAT_EV_SM0 << n)
        if changed & 2:
            v = _get32(self.mp, AL_EVENT_REQUEST)
            if mirror & 2:
                self._al_request(v | (EV_SM0 << n))
            elif v & (EV_SM0 << n):
                self._al_request(v & ~(EV_SM0 << n))

    def wd_pd_trigger(self) -> None:
        self.wd.trigger(self.ctx.t_ns)

    def check_timers(self, now_ns: int) -> None:
        """Run the watchdog; on expiry raise AL event 0x0220.6. Ref: §5.32, §5.42."""
        if self.wd.deadline_ns and self.wd.expired(now_ns):
            self.set_al_event(EV_WATCHDOG_PD)

    # ================================================================ ECAT face

    def ecat_read(self, ado: int, out: memoryview) -> int:
        """Physical read into ``out``; returns the WKC increment (0 or 1)."""
        end = ado + len(out)
        # SM windows lie in process RAM only (_compile_sm_windows): registers skip the look
        for ws, we, _sm in self.sm_windows if end > PDRAM_START else ():
            if ws < end and ado < we:
                return self._ecat_read_sm(ado, out)
        return 1 if self._plain_read(ado, out) else 0

    def ecat_read_system_time(self, out: memoryview) -> int:
        """``ecat_read(DC_SYSTEM_TIME, out)`` for the 4 or 8 bytes of 0x0910 that the FRMW
        of every DC cycle reads (decision P16): the register's one read hook, then its
        bytes, without the search through the hook table. Returns the WKC increment (1).
        Ref: TMC8460 §5.50.2 Table 95."""
        self.dc.refresh_system_time(self.ctx.t_ns)  # the hook DcUnit._er_system_time, inline
        mv = self.memv
        for k in range(len(out)):
            out[k] = mv[DC_SYSTEM_TIME + k]
        return 1

    def ecat_write_system_time(self, data: bytes) -> int:
        """``ecat_write(DC_SYSTEM_TIME, data)`` for the 4 or 8 bytes a writer of the DC time
        loops gets after the reply (decisions P7, P26): the register's masked bytes, then
        its one write hook's work (DcUnit._ew_system_time), without the search through
        the hook table. Returns the WKC increment (1). Ref: TMC8460 §5.50.2 Table 95."""
        n = len(data)
        wmask = self.ecat_wmask  # compiled: C pointers to the bytes (a register, P27)
        mem = self.mp  # compiled: the pointer kept (P62), no conversion per call (P76)
        d = data
        if n == 4 or n == 8:  # the masked bytes a 32-bit word at a time (decision P93)
            for k in range(0, n, 4):
                m = _get32(wmask, DC_SYSTEM_TIME + k)
                if (m >> 16) == 0xFFFF and (m & 0xFFFF) == 0xFFFF:  # writable: as written
                    mem[DC_SYSTEM_TIME + k] = d[k]
                    mem[DC_SYSTEM_TIME + k + 1] = d[k + 1]
                    mem[DC_SYSTEM_TIME + k + 2] = d[k + 2]
                    mem[DC_SYSTEM_TIME + k + 3] = d[k + 3]
                else:
                    v = _get32(mem, DC_SYSTEM_TIME + k)
                    _put32(mem, DC_SYSTEM_TIME + k, (v & ~m) | (_get32(d, k) & m))
        else:
            for k in range(n):
                m = wmask[DC_SYSTEM_TIME + k]
                if m:
                    mem[DC_SYSTEM_TIME + k] = (mem[DC_SYSTEM_TIME + k] & ~m) | (d[k] & m)
        self.wr_s = DC_SYSTEM_TIME
        self.wr_e = DC_SYSTEM_TIME + n
        ctx = self.ctx
        if self.dc.system_time_stored(ctx.t_ns, 8 if n >= 8 else 4):
            ctx.timers_dirty = True  # the clock jumped: SYNC deadlines moved
        return 1

    def ecat_read_or(self, ado: int, data: memoryview) -> int:
        """Broadcast read: the read data is ORed into the datagram. Ref: ETG.1000.4 §5.4.3."""
        n = len(data)
        tmp = self._scratch_view[:n]
        if not self.ecat_read(ado, tmp):
            return 0
        for k in range(n):  # compiled: a C loop
            data[k] |= tmp[k]
        return 1

    def ecat_write(self, ado: int, data: memoryview | bytes) -> int:
        """Physical write from ``data``; returns the WKC increment (0 or 1)."""
        end = ado + len(data)
        for ws, we, _sm in self.sm_windows if end > PDRAM_START else ():
            if ws < end and ado < we:
                return self._ecat_write_sm(ado, data)
        return 1 if self._plain_write(ado, data) else 0

    def _fmmu_xfer(self, f: FmmuMap, lad: int, data: memoryview, write: bool) -> bool:
        n = len(data)
        if f.aligned:
            lo = max(lad, f.lstart)
            hi = min(lad + n, f.lstop)
            phys = f.pstart + (lo - f.lstart)
            view = data[lo - lad : hi - lad]
            sm = f.sm
            if sm is not None:  # the whole map lies in one SM window: no window search
                if write:
                    if not sm.ecat_may_write():
                        return False
                    sm.ecat_write(phys - sm.start, view)
                    return True
                if not sm.ecat_may_read():
                    return False
                sm.ecat_read(phys - sm.start, view)
                return True
            if write:
                return bool(self.ecat_write(phys, view))
            return bool(self.ecat_read(phys, view))
        b0 = max(lad * 8, f.lbit)
        b1 = min((lad + n) * 8, f.lend)
        nb = b1 - b0
        pb = f.pbit + (b0 - f.lbit)
        ps = pb >> 3
        pe = (pb + nb + 7) >> 3
        fb = b0 - lad * 8
        if write:
            cur = bytearray(self.peek(ps, pe - ps))
            copy_bits(data, fb, cur, pb - ps * 8, nb)
            return bool(self.ecat_write(ps, memoryview(cur)))
        tmp = bytearray(pe - ps)
        if not self.ecat_read(ps, memoryview(tmp)):
            return False
        copy_bits(tmp, pb - ps * 8, data, fb, nb)
        return True

    def peek(self, addr: int, n: int) -> bytes:
        """Effective memory content without side effects (SM windows redirected)."""
        for ws, we, sm in self.sm_windows:
            if ws <= addr and addr + n <= we:
                return sm.peek(addr - ws, n)
        return bytes(self.mem[addr : addr + n])

    # -- SM windows ------------------------------------------------------------------

    def _hits(self, ado: int, end: int) -> list[tuple[int, int, SyncManager]]:
        return [w for w in self.sm_windows if w[0] < end and ado < w[1]]

    def _ecat_write_sm(self, ado: int, data: memoryview | bytes) -> int:
        end = ado + len(data)
        hits = self._hits(ado, end)
        for _ws, _we, sm in hits:
            if not sm.ecat_may_write():
                return 0
        pos = ado
        ok = True
        for ws, we, sm in hits:
            if pos < ws:
                ok &= self._plain_write(pos, data[pos - ado : ws - ado])
            s = max(pos, ws)
            e = min(end, we)
            if s < e:
                sm.ecat_write(s - ws, data[s - ado : e - ado])
                pos = e
        if pos < end:
            ok &= self._plain_write(pos, data[pos - ado :])
        return 1 if ok else 0

    def _ecat_read_sm(self, ado: int, out: memoryview) -> int:
        end = ado + len(out)
        hits = self._hits(ado, end)
        for _ws, _we, sm in hits:
            if not sm.ecat_may_read():
                return 0
        pos = ado
        ok = True
        for ws, we, sm in hits:
            if pos < ws:
                ok &= self._plain_read(pos, out[pos - ado : ws - ado])
            s = max(pos, ws)
            e = min(end, we)
            if s < e:
                sm.ecat_read(s - ws, out[s - ado : e - ado])
                pos = e
        if pos < end:
            ok &= self._plain_read(pos, out[pos - ado :])
        return 1 if ok else 0

    def _compile_sm_windows(self) -> None:
        """Address windows of the enabled SMs. An SM that starts below the process RAM is
        not mapped: the registers stay reachable, so a master can always reconfigure it.
        Ref: TMC8460 §5.49 (SM start address in process memory), §5.53; decision E22."""
        wins = []
        for sm in self.sm:
            if sm.active and sm.start >= PDRAM_START:
                wins.append((sm.start, sm.start + sm.length, sm))
        wins.sort(key=itemgetter(0))
        self.sm_windows = tuple(wins)
        self._route_fmmus()

    def _route_fmmus(self) -> None:
        """Give each byte-aligned FMMU the SM whose window holds its whole physical range
        (exactly one window may touch it), compiled when FMMUs or SM windows change. An
        SM with the ECAT latch event (0x0806+8n bit 6) is not given: its event time 0x09F0
        is kept by the window path (the compiled walk serves routed FMMUs only)."""
        for f in self.fmmus:
            f.sm = None
            if f.aligned:
                ps = f.pstart
                pe = ps + (f.lstop - f.lstart)
                hits = self._hits(ps, pe)
                if len(hits) == 1 and hits[0][0] <= ps and pe <= hits[0][1]:
                    sm = hits[0][2]
                    if not self.mem[sm.status_addr + 1] & SM_ACT_LATCH_ECAT:
                        f.sm = sm

    # -- plain memory ------------------------------------------------------------------

    def _plain_write(self, ado: int, data: memoryview | bytes) -> bool:
        end = ado + len(data)
        if end <= REGISTER_END:
            # bytes already (the DC time loops after the reply): no copy
            self.reg_write(ado, data if type(data) is bytes else bytes(data), False)
            return True
        if ado < REGISTER_END:
            self.reg_write(ado, bytes(data[: REGISTER_END - ado]), False)
            data = data[REGISTER_END - ado :]
            ado = REGISTER_END
        if not self.pdram_ok:
            return False
        e = min(end, PDRAM_END)
        if e > ado:
            self.mem[ado:e] = data[: e - ado]
            for sm in self.sm:  # an SM of length 1 is not activated: the watchdog trigger
                if sm.length == 1 and ado <= sm.start < e and sm.wd_tap():
                    self.wd_pd_trigger()
                    break
        return True

    def _plain_read(self, ado: int, out: memoryview) -> bool:
        end = ado + len(out)
        mv = self.memv
        if end <= REGISTER_END:
            self.reg_read_hooks(ado, end, False)
            for k in range(end - ado):  # compiled: a C loop (a slice copy is a generic call)
                out[k] = mv[ado + k]
            return True
        if ado < REGISTER_END:
            self.reg_read_hooks(ado, REGISTER_END, False)
            out[: REGISTER_END - ado] = mv[ado:REGISTER_END]
            out = out[REGISTER_END - ado :]
            ado = REGISTER_END
        if not self.pdram_ok:
            return False
        e = min(end, PDRAM_END)
        if e > ado:
            out[: e - ado] = mv[ado:e]
        for k in range(max(e, ado) - ado, end - ado):
            out[k] = 0  # past the process RAM
        return True

    def reg_write(self, s: int, data: bytes, pdi: bool) -> None:
        """Masked register write from the ECAT (``pdi`` False) or the PDI side: each byte
        keeps the bits its side may not write (the table's write masks), then the side
        effects of the registers touched run, each with its register's old value.
        Ref: TMC8460 §5 (register table, ECAT/PDI access columns)."""
        e = s + len(data)
        if pdi:
            wmask = self.pdi_wmask
            hooked = self.pdi_w_hooked
        else:
            wmask = self.ecat_wmask
            hooked = self.ecat_w_hooked
        mem = self.mem
        i = _first(hooked, s, e)
        old = bytes(mem[s:e]) if i >= 0 else b""
        if s < 0 or e > len(wmask):  # the pointers below: within the table's bounds
            raise IndexError(s)
        pm = mem  # compiled: C pointers, the indexes checked above (P58)
        pw = wmask
        pd = data
        for k in range(e - s):
            m = pw[s + k]
            if m:
                pm[s + k] = (pm[s + k] & ~m) | (pd[k] & m)
        self.wr_s = s
        self.wr_e = e
        if i < 0:
            return
        hooks = self.pdi_w_hooks if pdi else self.ecat_w_hooks
        change = self.ecat_w_change
        units = self.units
        while i >= 0:
            entry = hooks[i]
            if entry is None:  # pragma: no cover - bitmap and list are built together
                break
            fn, ra, rs = entry
            if pdi or not change[i] or self._changed(ra, rs, old, s):
                # the unit at the slot the bitmap holds (slot + 1), ecatsim/esc/dispatch.py
                fn(units[hooked[i] - 1], ra, rs, self.old_reg(ra, rs, old, s))
            i = _first(hooked, ra + rs, e) if ra + rs < e else -1

    def _changed(self, ra: int, rs: int, old: bytes, s: int) -> bool:
        """The write starting at ``s`` (the bytes before it: ``old``) changed a byte of the
        register [ra, ra + rs) (decision P20)."""
        mem = self.mem
        lo = max(ra, s)
        hi = min(ra + rs, s + len(old), len(mem))
        pm = mem  # compiled: C pointers (any() is a generator), the bounds above
        po = old
        for a in range(lo, hi):  # noqa: SIM110
            if pm[a] != po[a - s]:
                return True
        return False

    def reg_read_hooks(self, s: int, e: int, pdi: bool) -> None:
        """The read side effects of the registers in [s, e) for the ECAT (``pdi`` False)
        or the PDI side, before the bytes are taken from memory. Ref: TMC8460 §5."""
        hooked = self.pdi_r_hooked if pdi else self.ecat_r_hooked
        i = _first(hooked, s, e)
        if i < 0:
            return
        hooks = self.pdi_r_hooks if pdi else self.ecat_r_hooks
        units = self.units
        while i >= 0:
            entry = hooks[i]
            if entry is None:  # pragma: no cover
                break
            fn, ra, rs = entry
            if ra == DC_SYSTEM_TIME:
                # the FRMW of every cycle reads it: the hooks DcUnit._er_system_time and
                # _pr_system_time inline, C calls with the frame's times when compiled (P14)
                if not pdi:
                    self.dc.refresh_system_time(self.ctx.t_ns)
                elif s <= ra:  # PDI: latched when the first byte is read (Table 95)
                    self.dc.latch_system_time(self.ctx.pdi_ns)
            elif pdi and ra in (DC_SYNC0_STATUS, DC_SYNC1_STATUS):
                # the firmware acknowledges every SYNC0 pulse: the hook
                # DcUnit._pr_sync_status as C calls when compiled (P25)
                self.clr_al_event(self.dc.sync_status_read(ra))
            else:
                fn(units[hooked[i] - 1], ra, rs)
            i = _first(hooked, ra + rs, e) if ra + rs < e else -1

    def old_reg(self, ra: int, rs: int, old: bytes, s: int) -> bytes:
        """The register's value before the write (bytes outside the write are unchanged)."""
        if s <= ra and ra + rs <= s + len(old):  # the write covered the whole register
            return old[ra - s : ra - s + rs]
        lo = max(ra, s)
        hi = min(ra + rs, s + len(old))
        return bytes(self.mem[ra:lo]) + old[lo - s : hi - s] + bytes(self.mem[hi : ra + rs])

    # ================================================================ the ESC's own hooks
    # (side_effect esc.<name>; the other units' hooks are theirs: ecatsim/esc/dispatch.py)

    def _ec_station_address(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.9: the configured station address used by FPxx commands."""
        self.ctx.addr_dirty = True

    def _pw_station_alias(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.10: alias written by the PDI, active with 0x0100.24."""
        self.ctx.addr_dirty = True

    def _ew_reset_ecat(self, ra: int, rs: int, old: bytes) -> None:
        """'R','E','S' in three consecutive frames resets the ESC. Ref: TMC8460 §5.15."""
        v = self.mem[ra]
        prog = old[0] & 0x03
        f = self.ctx.frame_no
        consecutive = f == self.reset_progress_frame + 1
        if v == 0x52:
            self.mem[ra] = 0x01
        elif v == 0x45 and prog == 0x01 and consecutive:
            self.mem[ra] = 0x02
        elif v == 0x53 and prog == 0x02 and consecutive:
            self.hardware_reset()
            return
        else:
            self.mem[ra] = 0x00
        self.reset_progress_frame = f

    def _pw_reset_pdi(self, ra: int, rs: int, old: bytes) -> None:
        """'R','E','S' in three consecutive PDI writes resets the ESC. Ref: TMC8460 §5.16."""
        v = self.mem[ra]
        prog = old[0] & 0x03
        if v == 0x52:
            self.mem[ra] = 0x01
        elif v == 0x45 and prog == 0x01:
            self.mem[ra] = 0x02
        elif v == 0x53 and prog == 0x02:
            self.hardware_reset()
        else:
            self.mem[ra] = 0x00

    def hardware_reset(self) -> None:
        """Reset the ESC (and, through on_reset, the application behind the PDI)."""
        self.power_on()
        self._compile_sm_windows()
        if self.on_reset is not None:
            self.on_reset()

    def _ec_dl_control(self, ra: int, rs: int, old: bytes) -> None:
        """Loop 0x0101: DL status, routes; bit 24: alias; no other bit (P57). Ref: TMC8460 §5.17"""
        if self.mem[DL_CONTROL + 1] != old[1]:
            self.update_dl_status()
            self.ctx.topology_dirty = True
        self.ctx.addr_dirty |= bool((self.mem[DL_CONTROL + 3] ^ old[3]) & 0x01)

    def _er_dl_status(self, ra: int, rs: int) -> None:
        """Reading DL status clears ECAT event 0x0210.2. Ref: TMC8460 §5.19 note *."""
        self._clr_ecat_event(ECAT_EV_DL_STATUS)

    def _ew_al_control(self, ra: int, rs: int, old: bytes) -> None:
        """AL control: copied to AL status in device emulation, else an AL event to the PDI
        that locks the register until the PDI reads it. Ref: TMC8460 §5.20, §5.26 bit 0."""
        m = self.mem
        if m[ESC_CONFIG] & 0x01:
            new = m[ra] | (m[ra + 1] << 8)
            st = m[AL_STATUS] | (m[AL_STATUS + 1] << 8)
            self.set_al_status((st & ~0x3F) | (new & 0x2F))
            return
        if self.al_control_locked:
            m[ra : ra + rs] = old
            return
        self.al_control_locked = True
        self.set_al_event(EV_AL_CONTROL)

    def set_al_status(self, value: int) -> None:
        """Write AL status; a change raises ECAT event 0x0210.3. Ref: TMC8460 §5.21, §5.31."""
        m = self.mem
        old = m[AL_STATUS] | (m[AL_STATUS + 1] << 8)
        _put16(m, AL_STATUS, value & 0xFFFF)
        if old != value:
            self._set_ecat_event(ECAT_EV_AL_STATUS)

    def _er_al_status(self, ra: int, rs: int) -> None:
        """Reading AL status clears ECAT event 0x0210.3. Ref: TMC8460 §5.21 note *."""
        self._clr_ecat_event(ECAT_EV_AL_STATUS)

    def _ec_ecat_event_mask(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.29 (mask for the IRQ field)."""
        self._irq_update()

    def _ew_rx_error_counter(self, ra: int, rs: int, old: bytes) -> None:
        """Writing any RX error counter clears 0x0300-0x030B. Ref: TMC8460 §5.33, §5.34."""
        self.mem[RX_ERROR_COUNTER:ECAT_PU_ERROR_COUNTER] = bytes(12)

    def _ew_ecat_pu_error_counter(self, ra: int, rs: int, old: bytes) -> None:
        """Writing 0x030C clears it. Ref: TMC8460 §5.35."""
        self.mem[ECAT_PU_ERROR_COUNTER] = 0

    def _ew_pdi_error_counter(self, ra: int, rs: int, old: bytes) -> None:
        """Writing 0x030D clears it and 0x030E. Ref: TMC8460 §5.36, §5.37."""
        self.mem[PDI_ERROR_COUNTER] = 0
        self.mem[PDI_ERROR_CODE] = 0

    def _ew_lost_link_counter(self, ra: int, rs: int, old: bytes) -> None:
        """Writing any lost link counter clears 0x0310-0x0313. Ref: TMC8460 §5.38."""
        self.mem[LOST_LINK_COUNTER : LOST_LINK_COUNTER + 4] = bytes(4)

    def _ec_fmmu(self, ra: int, rs: int, old: bytes) -> None:
        """Recompile the FMMU maps when any FMMU register changes. Ref: TMC8460 §5.48."""
        self.fmmus = compile_fmmus(self.mem)
        self._route_fmmus()
        self.ctx.logical_dirty = True

    def _ec_sm(self, ra: int, rs: int, old: bytes) -> None:
        """The SyncManagers' start, length, control and activate registers, one call per
        write of the block (P20, P58). Start, length and control take a write only while
        their SM is disabled (its state before this write); a change of the enable bit
        restarts the SM, of the ECAT event bit routes the FMMUs anew, any change of an
        activate byte raises AL event 0x0220.4; the windows are compiled once. Ref: TMC8460
        §5.49 Tables 86-88 (r/(w)), Table 90; §5.32 Table 46 bit 4."""
        if ra != SM_BASE or rs != N_SM * SM_STRIDE or len(old) < rs:  # the pointers below
            raise IndexError(ra)
        m = self.mem  # compiled: C pointers to the registers and the block's old bytes
        po = old
        windows = route = event = False
        for n in range(N_SM):
            a = SM_BASE + n * SM_STRIDE
            o = a - ra
            sm = self.sm[n]
            if sm.enabled:
                for k in range(5):
                    m[a + k] = po[o + k]
            d = m[a + 6] ^ po[o + 6]
            if d & SM_ACT_ENABLE:
                self._sm_configure(n)
                windows = True
            elif d & SM_ACT_LATCH_ECAT:
                route = True  # an SM with ECAT event times is left to the Python path
            event = event or d != 0
        if windows:
            self._compile_sm_windows()
        elif route:
            self._route_fmmus()
        if event:
            self.set_al_event(EV_SM_ACTIVATION)

    def _ec_sm_activate(self, ra: int, rs: int, old: bytes) -> None:
        """An ECAT write of an activate register alone: the block hook (``_ec_sm``)."""
        self._ec_sm(ra, rs, old)

    def _pr_sm_activate(self, ra: int, rs: int) -> None:
        """PDI read of an activate register clears AL event 0x0220.4 (§5.49 Table 90 *)."""
        self.clr_al_event(EV_SM_ACTIVATION)

    def _sm_configure(self, n: int) -> None:
        """(Re)start SM ``n`` with its registers. Ref: TMC8460 §5.49 Tables 86-91."""
        p = self.mem  # compiled: a C pointer (registers only)
        b = SM_BASE + n * SM_STRIDE
        sm = self.sm[n]
        sm.configure(p[b] | (p[b + 1] << 8), p[b + 2] | (p[b + 3] << 8), p[b + 4],
                     (p[b + 6] & SM_ACT_ENABLE) != 0, (p[b + 7] & 0x01) != 0)  # fmt: skip

    def sm_restart(self, n: int) -> None:
        self._sm_configure(n)
        self._compile_sm_windows()

    def _pr_al_control(self, ra: int, rs: int) -> None:
        """PDI read of AL control clears AL event 0x0220.0 and unlocks the register.
        Ref: TMC8460 §5.20 note, §5.32 bit 0."""
        self.al_control_locked = False
        self.clr_al_event(EV_AL_CONTROL)

    def _pw_al_status(self, ra: int, rs: int, old: bytes) -> None:
        """PDI writes AL status only with device emulation off. Ref: TMC8460 §5.21 note."""
        m = self.mem
        if m[ESC_CONFIG] & 0x01:
            m[ra : ra + rs] = old
            return
        if bytes(m[ra : ra + rs]) != old:
            self._set_ecat_event(ECAT_EV_AL_STATUS)

    def _pw_al_event_mask(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.30 (mask for the PDI interrupt)."""
        self._pdi_irq(_get32(self.mem, AL_EVENT_REQUEST))

    def sync0_tick(self, now_ns: int) -> None:
        """A due SYNC0 pulse: status, and AL event 0x0220.2 if mapped. Ref: §5.32 bit 2."""
        if self.dc.sync0_pulse(now_ns):
            self.set_al_event(EV_SYNC0)
        if not self.dc.sync0_on:
            self.ctx.timers_dirty = True  # single shot: this ESC's SYNC unit is done

    def sync1_tick(self) -> None:
        """A due SYNC1 pulse: status, and AL event 0x0220.3 if mapped. Ref: §5.32 bit 3."""
        if self.dc.sync1_pulse():
            self.set_al_event(EV_SYNC1)

    def latch_input(self, unit: int, level: bool, host_ns: int) -> None:
        """The LATCH ``unit`` pin is driven to ``level`` at host time ``host_ns`` (the DC
        unit's latch in unit). Ref: TMC8460 §5.50.5."""
        self.dc.latch_input(unit, level, host_ns)

    # -- SyncManager event times (TMC8460 §5.50.6) ----------------------------------------

    def sm_event_time(self, reg: int) -> None:
        """An SM with a latch event bit (0x0806+8n bit 6/7) exchanged a buffer: 0x09F0
        takes the local time of the frame's beginning (ECAT), 0x09F8/0x09FC the local time
        of the PDI access. Ref: TMC8460 §5.50.6 Tables 122-124, §5.49 Table 90."""
        ctx = self.ctx
        t = self.dc.arrival_ns(ctx.t_ns) if reg == DC_ECAT_EVENT_TIME else ctx.pdi_ns
        _put32(self.mem, reg, self.dc.local_time(t) & 0xFFFFFFFF)

    def pdi_buffer_event(self, sm: SyncManager, first: bool, last: bool) -> None:
        """A PDI access of SM ``sm``'s buffer: its start address is a PDI buffer start
        event, its last byte a PDI buffer change event, if 0x0806+8n bit 7 asks for them.
        Ref: TMC8460 §5.49 Table 90 bit 7, §5.50.6 Tables 123, 124."""
        if self.mem[sm.status_addr + 1] & SM_ACT_LATCH_PDI:
            if first:
                self.sm_event_time(DC_PDI_START_EVENT_TIME)
            if last:
                self.sm_event_time(DC_PDI_CHANGE_EVENT_TIME)
