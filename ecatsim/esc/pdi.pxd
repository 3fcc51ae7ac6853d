# The compiled core's declarations for pdi.py (Cython, pure-Python mode): the PDI face as
# a typed class, so the compiled firmware reaches the ESC through these calls and nothing
# else. pdi.py stays the one source of the behaviour; this file only gives types.
# Decisions P2, P13.
cimport cython
# int64_t, not long long, for the methods of a final type with an exception value (core.pxd)
from libc.stdint cimport int64_t

from ecatsim.esc.core cimport Esc
from ecatsim.esc.sm cimport SyncManager

cdef long long _REG_END, _DL_STATUS, _SYNC0_STATUS, _SYNC1_STATUS


# what fills an SM's buffer in place (the firmware's process image derives from it: P71)
cdef class SmImage:
    cpdef bint fill(self, bytearray mem, long long base, long long n) except -1


@cython.final
cdef class Pdi:
    cdef public Esc _esc

    cpdef bint operational(self) except -1
    @cython.locals(esc=Esc, end="long long", ws="long long", we="long long", sm=SyncManager)
    cpdef bytes read(self, long long addr, long long n)
    @cython.locals(esc=Esc, end="long long", ws="long long", we="long long", sm=SyncManager,
                   n="long long", split="long long")
    cpdef bint write(self, long long addr, object data) except -1
    @cython.locals(esc=Esc, hooked=bytes)
    cpdef int64_t u8(self, long long addr) except -1
    @cython.locals(esc=Esc, hooked=bytes, m=bytearray)
    cpdef int64_t u16(self, long long addr) except -1
    @cython.locals(esc=Esc, m=bytearray, b3="long long")
    cpdef int64_t u32(self, long long addr) except -1
    cpdef void w16(self, long long addr, long long value) except *
    cpdef void w32(self, long long addr, long long value) except *
    cpdef int64_t al_event(self) except -1
    @cython.locals(esc=Esc, sm=SyncManager)
    cpdef object sm_read(self, long long n)
    @cython.locals(esc=Esc, sm=SyncManager)
    cpdef bint sm_write(self, long long n, object data) except -1
    @cython.locals(esc=Esc, sm=SyncManager)
    cpdef bint sm_read_into(self, long long n, bytearray out) except -1
    @cython.locals(esc=Esc, sm=SyncManager, size="long long", base="long long")
    cpdef bint sm_fill(self, long long n, SmImage image) except -1
