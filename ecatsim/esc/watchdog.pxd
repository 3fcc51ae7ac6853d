# The compiled core's declarations for watchdog.py (Cython, pure-Python mode). P2, P13.
cimport cython

from ecatsim.esc.context cimport FrameContext

# the registers, imported from regs.py: C constants here
cdef long long EV_WATCHDOG_PD, WD_COUNTER_PD, WD_COUNTER_PDI, WD_DIVIDER, WD_STATUS_PD, WD_TIME_PD


@cython.final
cdef class Watchdog:
    cdef public FrameContext ctx
    cdef public object esc  # the ESC (ecatsim.esc.core.Esc), for the AL event register
    cdef public bytearray mem
    cdef public long long deadline_ns, increment_ns, timeout_ns

    # noexcept: each process-data write of the frame walk triggers it (P62)
    @cython.locals(p="unsigned char*", d="long long", ctx=FrameContext)
    cpdef void trigger(self, long long now_ns) noexcept
    cpdef bint expired(self, long long now_ns) except -1
