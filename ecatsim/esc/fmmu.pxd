cimport cython
# The compiled core's declarations for fmmu.py (Cython, pure-Python mode): one FMMU's
# compiled map as typed fields. Decisions P2, P13.
from ecatsim.esc.sm cimport SyncManager


@cython.final
cdef class FmmuMap:
    cdef public long long lbit, lend, pbit, lstart, lstop, pstart
    cdef public bint read, write, aligned
    cdef public SyncManager sm
    cdef public FmmuMap wnext, rnext

cdef long long FMMU_BASE, FMMU_STRIDE, N_FMMU


@cython.locals(p="const unsigned char*", n="long long", a="long long", f=FmmuMap, w=FmmuMap,
               r=FmmuMap)
cpdef tuple compile_fmmus(bytearray mem)

cdef long long LRD, LRW, LWR


# the frame walk's logical path (P61); esc: the ESC (ecatsim.esc.core.Esc), for an FMMU
# without an SM
@cython.locals(end="long long", a="long long", wr=bint, rd=bint, f=FmmuMap, head=FmmuMap,
               sm=SyncManager)
cpdef long long logical_at(object esc, tuple fmmus, long long cmd, long long lad, bytearray buf,
                           long long pos, long long n) except -1
