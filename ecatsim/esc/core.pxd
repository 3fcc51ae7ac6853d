# The compiled core's declarations for core.py (Cython, pure-Python mode): the ESC's and
# the frame context's state as typed fields. core.py stays the one source of the
# behaviour; this file only gives types. Decisions P2, P13.
from ecatsim.esc.context cimport FrameContext
from ecatsim.esc.dc cimport DcUnit
from ecatsim.esc.fmmu cimport FmmuMap, compile_fmmus
from ecatsim.esc.sm cimport SmHost, SyncManager
from ecatsim.esc.watchdog cimport Watchdog


cimport cython
# int64_t, not long long, for the methods of a final type with an exception value:
# Cython 3.3 writes long long's value there as -1LLLL in pure-Python mode
from libc.stdint cimport int64_t

# the registers, imported from regs.py: C constants here
cdef long long AL_EVENT_MASK, AL_EVENT_REQUEST, AL_STATUS, DC_ECAT_EVENT_TIME
cdef long long DC_PDI_CHANGE_EVENT_TIME, DC_PDI_START_EVENT_TIME, DC_SYSTEM_TIME, DL_CONTROL
cdef long long DC_SYNC0_STATUS, DC_SYNC1_STATUS
cdef long long DL_STATUS, ECAT_EV_AL_STATUS, ECAT_EV_DL_STATUS, ECAT_EV_SM0, ECAT_EVENT_MASK
cdef long long ECAT_EVENT_REQUEST, ECAT_PU_ERROR_COUNTER, ESC_CONFIG, EV_AL_CONTROL, EV_SM0
cdef long long EV_SYNC0, EV_SYNC1, EV_WATCHDOG_PD, LOST_LINK_COUNTER, N_SM, PDI_ERROR_CODE
cdef long long PDI_ERROR_COUNTER, PDRAM_END, PDRAM_START, REGISTER_END, RX_ERROR_COUNTER
cdef long long SM_ACT_LATCH_ECAT, SM_ACT_LATCH_PDI, WD_COUNTER_PDI, EV_SM_ACTIVATION, SM_ACT_ENABLE
cdef long long SM_BASE, SM_STRIDE
cdef long long WD_STATUS_PD


# the register helpers inline: a few loads or stores each, called at every event (P46);
# they take a pointer (a caller's bytearray is made one where it calls), so they cannot
# raise (P62)
@cython.locals(b3="long long", p="const unsigned char*")
cdef inline long long _get32(const unsigned char* m, long long a) noexcept
@cython.locals(i="long long", p="const unsigned char*")
cdef long long _first(bytes hooked, long long s, long long e) except? -2
@cython.locals(p="unsigned char*")
cdef inline void _put16(unsigned char* m, long long a, long long v) noexcept
@cython.locals(p="unsigned char*")
cdef inline void _put32(unsigned char* m, long long a, long long v) noexcept


@cython.final
cdef class Esc(SmHost):
    cdef public long long position
    cdef public bint pdi_emulation
    cdef public FrameContext ctx
    cdef public bytearray mem
    cdef unsigned char[:] memv
    cdef unsigned char* mp
    cdef public object t
    cdef public bytes ecat_wmask, pdi_wmask, ecat_w_hooked, pdi_w_hooked, ecat_r_hooked
    cdef public bytes pdi_r_hooked, ecat_w_change
    cdef public tuple ecat_w_hooks, pdi_w_hooks, ecat_r_hooks, pdi_r_hooks
    # the units whose hooks the register table names (ecatsim/esc/dispatch.py)
    cdef public tuple units
    cdef public list sm
    cdef public object eeprom
    cdef public DcUnit dc
    cdef public Watchdog wd
    cdef public object mii
    cdef public tuple fmmus
    cdef public tuple sm_windows
    cdef public bint pdram_ok
    cdef public long long ports, wired, ports_link, ports_open
    cdef public bint port1_closed, port0_open, port0_closed
    cdef public list link_down
    cdef public bint al_control_locked
    cdef public long long reset_progress_frame
    cdef public long long ecat_irq
    cdef public bint irq_line
    cdef public long long wr_s, wr_e
    cdef public bytearray _scratch
    cdef unsigned char[:] _scratch_view
    cdef public object on_reset

    @cython.locals(n="long long", lo="long long", hi="long long", wr=bint, rd=bint, f=FmmuMap)
    @cython.locals(n="long long", lo="long long", hi="long long", phys="long long",
                   sm=SyncManager, view="unsigned char[:]", b0="long long", b1="long long", nb="long long",
                   pb="long long", ps="long long", pe="long long", fb="long long")
    cpdef bint _fmmu_xfer(self, FmmuMap f, long long lad, unsigned char[:] data, bint write) except -1
    @cython.locals(m="unsigned char*", v="long long")
    cpdef void _set_ecat_event(self, long long bits) noexcept
    @cython.locals(m="unsigned char*", v="long long")
    cpdef void _clr_ecat_event(self, long long bits) noexcept
    @cython.locals(m="unsigned char*", req="long long", mask="long long", irq="long long")
    cpdef void _irq_update(self) noexcept
    cpdef int64_t al_event(self) except -1
    cpdef void pdi_buffer_event(self, SyncManager sm, bint first, bint last) except *
    cpdef void set_al_event(self, long long bits) noexcept
    @cython.locals(v="long long")
    cpdef void clr_al_event(self, long long bits) noexcept
    cdef inline void _al_request(self, long long v) noexcept
    @cython.locals(line=bint)
    cdef inline void _pdi_irq(self, long long request) noexcept
    # sm_status_changed, wd_pd_trigger, sm_event_time: SmHost's, overridden in core.py (a
    # final type may not declare its overrides again here)
    @cython.locals(v="long long")
    cdef inline void _sm_events(self, long long mirror, long long n, long long changed) noexcept
    cpdef void sync0_tick(self, long long now_ns) except *
    cpdef void sync1_tick(self) except *
    # the encoder index pulse of a drive in motion, to the latch in unit: C calls (P49)
    cpdef void latch_input(self, long long unit, bint level, long long host_ns) except *
    @cython.locals(end="long long", ws="long long", we="long long")
    cpdef int64_t ecat_read(self, long long ado, unsigned char[:] out) except -1
    @cython.locals(n="long long", k="long long", m="long long", v="long long",
                   wmask="const unsigned char*", mem="unsigned char*", d="const unsigned char*",
                   ctx=FrameContext)
    cpdef int64_t ecat_write_system_time(self, bytes data) except -1
    @cython.locals(n="long long", k="long long", tmp="unsigned char[:]")
    cpdef int64_t ecat_read_or(self, long long ado, unsigned char[:] data) except -1
    @cython.locals(mv="unsigned char[:]", k="long long")
    cpdef int64_t ecat_read_system_time(self, unsigned char[:] out) except -1
    @cython.locals(end="long long", ws="long long", we="long long")
    cpdef int64_t ecat_write(self, long long ado, object data) except -1
    @cython.locals(end="long long", e="long long")
    cpdef bint _plain_write(self, long long ado, object data) except -1
    @cython.locals(end="long long", e="long long", k="long long", mv="unsigned char[:]")
    cpdef bint _plain_read(self, long long ado, unsigned char[:] out) except -1
    @cython.locals(e="long long", i="long long", k="long long", m="long long",
                   wmask=bytes, hooked=bytes, change=bytes, mem=bytearray, hooks=tuple,
                   entry=tuple, ra="long long", rs="long long", units=tuple,
                   pm="unsigned char*", pw="const unsigned char*", pd="const unsigned char*")
    cpdef void reg_write(self, long long s, bytes data, bint pdi) except *
    @cython.locals(mem=bytearray, lo="long long", hi="long long", a="long long",
                   pm="const unsigned char*", po="const unsigned char*")
    cpdef bint _changed(self, long long ra, long long rs, bytes old, long long s) except -1
    @cython.locals(lo="long long", hi="long long")
    cpdef bytes old_reg(self, long long ra, long long rs, bytes old, long long s)
    @cython.locals(i="long long", hooked=bytes, hooks=tuple, entry=tuple, ra="long long",
                   rs="long long", units=tuple)
    cpdef void reg_read_hooks(self, long long s, long long e, bint pdi) except *
    # the SM block's ECAT write hook and the SM restart: C calls, the windows once (P58)
    @cython.locals(m="unsigned char*", po="const unsigned char*", windows=bint, route=bint,
                   event=bint, n="long long", a="long long", o="long long", k="long long",
                   d="long long", sm=SyncManager)
    cpdef void _ec_sm(self, long long ra, long long rs, bytes old) except *
    @cython.locals(p="const unsigned char*", b="long long", sm=SyncManager)
    cpdef void _sm_configure(self, long long n) except *
    @cython.locals(wins=list, sm=SyncManager)
    cpdef void _compile_sm_windows(self) except *
    @cython.locals(f=FmmuMap, ps="long long", pe="long long", hits=list, sm=SyncManager)
    cpdef void _route_fmmus(self) except *
    cpdef list _hits(self, long long ado, long long end)
