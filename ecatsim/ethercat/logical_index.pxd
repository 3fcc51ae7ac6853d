# The compiled core's declarations for logical_index.py (Cython, pure-Python mode): the
# FMMU ranges as C arrays and the lookup's locals as C integers. logical_index.py stays the
# one source of the behaviour; this file only gives types. Decisions P2, P13, P99.
cimport cython

from ecatsim.esc.core cimport Esc
from ecatsim.esc.fmmu cimport logical_at

cdef long long INDEX_MIN


cdef class LogicalIndex:
    cdef public list escs
    cdef long long[:] _start, _stop, _k
    cdef public long long _reach, _last
    # a view of the bytearray, made once per build
    cdef unsigned char[:] _mark
    cdef public bint on
    cdef public long long visits

    # build() is a Python method: it runs when an FMMU or the route changes

    @cython.locals(escs=list, inc="long long", end="long long", esc=Esc, n="long long",
                   key="long long", lo="long long", hi="long long", mid="long long",
                   kmin="long long", kmax="long long", j="long long", k="long long",
                   start="long long[:]", stop="long long[:]", ks="long long[:]",
                   mark="unsigned char[:]")
    cpdef long long walk(self, long long cmd, long long lad, bytearray buf, long long d0,
                         long long dlen) except -1
