cimport cython
# The compiled core's declarations for fmmu.py (Cython, pure-Python mode): one FMMU's
# compiled map as typed fields. Decisions P2, P13.
from ecatsim.esc.sm cimport SyncManager


@cython.final
cdef class FmmuMap:
    cdef public long long lbit, lend, pbit, lstart, lstop, pstart
    cdef public bint read, write, aligned
    cdef public SyncManager sm

cdef long long FMMU_BASE, FMMU_STRIDE, N_FMMU


@cython.locals(p="const unsigned char*", n="long long", a="long long", f=FmmuMap)
cpdef tuple compile_fmmus(bytearray mem)
