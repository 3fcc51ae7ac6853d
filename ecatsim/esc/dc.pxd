# The compiled core's declarations for dc.py (Cython, pure-Python mode): the DC unit's
# state as typed fields. The clock is C integers: dc.py keeps every value of it modulo
# 2^64 in the source, so Python's unbounded integers and C's agree; the rates are C
# doubles computed in the same order as Python (built -ffp-contract=off). The SYNC
# deadlines' API stays Python integers (None while off); the SYNC0 pulse's own time is C
# fields (P42). Decisions P2, P13.
cimport cython
# int64_t, not long long, for the methods of a final class with an exception value:
# Cython 3.3 writes long long's value there as -1LLLL in pure-Python mode
from libc.stdint cimport int64_t

cdef unsigned long long MASK64, HALF64
cdef long long HALF32, NO_STAMP, LATER, MOVE_NS
# the registers, imported from regs.py: C constants here
cdef long long CUC_LATCH0_PDI, CUC_SYNC_PDI, DC_ACTIVATION, DC_ACTIVATION_STATUS
cdef long long DC_CYCLIC_UNIT_CONTROL, DC_LATCH0_CONTROL, DC_LATCH0_POS, DC_LATCH0_STATUS
cdef long long DC_NEXT_SYNC1, DC_PULSE_LENGTH, DC_RECV_TIME_P0, DC_RECV_TIME_PU
cdef long long DC_SPEED_COUNTER_DIFF, DC_SPEED_COUNTER_START, DC_START_TIME, DC_SYNC0_CYCLE
cdef long long DC_SYNC0_STATUS, DC_SYNC1_CYCLE, DC_SYNC1_STATUS, DC_SYSTEM_TIME
cdef long long DC_SYSTEM_TIME_DELAY, DC_SYSTEM_TIME_DIFF, DC_SYSTEM_TIME_OFFSET
cdef long long DC_TIME_DIFF_FILTER, ECAT_EV_DC_LATCH, ESC_CFG_LATCH_IN, ESC_CFG_SYNC_OUT
cdef long long ESC_CONFIG, EV_DC_LATCH, EV_SYNC0, EV_SYNC1, SYNC_LATCH_CONFIG


# a C cast and a C conditional: inline, no error test after each call (P76)
@cython.locals(k="long long")
cdef inline long long _trunc(double x) noexcept
cdef inline long long _signed64(unsigned long long x) noexcept
# the register helpers inline (P46), on the unit's pointer to the memory: they cannot
# raise, so no error test follows their calls (P85)
@cython.locals(lo="unsigned long long", hi="unsigned long long", b3="unsigned long long",
               b7="unsigned long long", p="const unsigned char*")
cdef inline unsigned long long _get64(const unsigned char* m, long long a) noexcept
@cython.locals(b3="unsigned long long", p="const unsigned char*")
cdef inline unsigned long long _get32(const unsigned char* m, long long a) noexcept
@cython.locals(p="unsigned char*")
cdef inline void _put64(unsigned char* m, long long a, unsigned long long v) noexcept
@cython.locals(p="unsigned char*")
cdef inline void _put32(unsigned char* m, long long a, unsigned long long v) noexcept


@cython.final
cdef class DcUnit:
    # the ESC (ecatsim.esc.core.Esc): its frame context, write range and events, for the
    # register hooks
    cdef public object esc
    cdef public bytearray mem
    # the memory's bytes (mem, never resized: the ESC's view holds its buffer), P85
    cdef unsigned char* mp
    cdef public long long position, hop_ns, turnaround_ns, sync1_countdown
    cdef public long long arrive_ns, latch_wait
    cdef public list port_ns
    cdef public double drift_ppm, rate_ppb, spd
    cdef public long long moved_ns, t_ref
    cdef public unsigned long long local_ref
    cdef public object next_sync1
    # the next SYNC0 pulse (next_sync0, a property): C fields (decision P42)
    cdef public bint sync0_on
    cdef public unsigned long long sync0_at

    cpdef int64_t arrival_ns(self, long long frame_t_ns) except? -1
    cpdef unsigned long long local_time(self, long long t_ns) except? 0
    cpdef void _set_rate(self, double rate_ppb) noexcept
    cpdef unsigned long long offset(self) except? 0
    cpdef unsigned long long system_time(self, long long t_ns) except? 0
    cpdef void refresh_system_time(self, long long frame_t_ns) except *
    cpdef void latch_system_time(self, long long t_ns) except *
    @cython.locals(t="long long", delay="unsigned long long",
                   offset="unsigned long long", local_now="unsigned long long",
                   local="unsigned long long", diff="long long", start="long long",
                   gain=double, step="long long", mag="long long", p="unsigned char*")
    cpdef bint system_time_written(self, long long frame_t_ns, unsigned long long value, long long nbytes) except -1
    cpdef int64_t host_time_of(self, object system_ns) except? -1
    @cython.locals(local="long long")
    cpdef int64_t _host_time(self, unsigned long long system_ns) except? -1
    cpdef object sync0_deadline(self)
    @cython.locals(n0="unsigned long long", cycle="long long",
                   behind="long long", p="unsigned char*", local="unsigned long long",
                   now_sys="unsigned long long")
    cpdef bint sync0_pulse(self, long long now_ns) except -1
    cpdef void _schedule_sync1(self, object sync0_time, object cycle0) except *
    cpdef object sync1_deadline(self)
    @cython.locals(local="long long", offset="unsigned long long")
    cpdef int64_t sync0_deadline_or(self, long long none) except? -1
    cpdef int64_t sync1_deadline_or(self, long long none) except? -1
    cpdef bint sync1_pulse(self) except -1
    # the latch in unit, driven by a drive's encoder index pulse: C calls (P49)
    @cython.locals(m=bytearray)
    cpdef void latch_input(self, long long unit, bint level, long long host_ns) except *
    @cython.locals(m=bytearray, status="long long", bit="long long", single="long long",
                   reg="long long")
    cpdef bint latch_edge(self, long long unit, bint rising, long long host_ns) except -1
    cpdef bint latch_pdi(self, long long unit) except -1
    @cython.locals(lim="long long", x="long long", p="unsigned char*")
    cpdef void _speed_counter_diff(self, long long start) noexcept
    # the register hooks that the frames of every DC cycle run: C calls from the ESC
    cpdef void _er_system_time(self, long long ra, long long rs) except *
    cpdef void _pr_system_time(self, long long ra, long long rs) except *
    cpdef void _pr_sync_status(self, long long ra, long long rs) except *
    @cython.locals(m=bytearray)
    cpdef int64_t sync_status_read(self, long long ra) except? -1
    cpdef void _ew_system_time(self, long long ra, long long rs, object old) except *
    @cython.locals(value="unsigned long long")
    cpdef bint system_time_stored(self, long long frame_t_ns, long long nbytes) except -1
