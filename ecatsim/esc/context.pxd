# The compiled core's declarations for context.py (Cython, pure-Python mode): the frame
# context's state as typed fields. Decisions P2, P13.
cimport cython


@cython.final
cdef class FrameContext:
    cdef public long long frame_no
    cdef public long long t_ns, pdi_ns, wd_next
    cdef public bint irq_dirty, addr_dirty, logical_dirty, topology_dirty, timers_dirty
    cdef public bint latch_wait
    cdef public bytearray raised
    cdef public long long n_raised
    cdef public set flush

    # noexcept: the event paths below only move bits in memory and these fields (P48)
    @cython.locals(r=bytearray, v="long long")
    cpdef void set_raised(self, long long position, bint line) noexcept
