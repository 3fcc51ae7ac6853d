# The compiled core's declarations for drive_od.py (Cython, pure-Python mode): the drive's
# bound entries as typed fields and its published values' ranges as C arrays. drive_od.py
# stays the one source of the behaviour; this file only gives types. Decision P2.
cimport cython

from ecatsim.slave.od cimport Entry
from ecatsim.slave.pdo cimport CycleDevice


cdef class DriveOd(CycleDevice):
    cdef public object od
    cdef public dict _entries
    cdef public object _published
    cdef public object _snapshot_hits
    cdef public object _control_hits
    cdef bint _bound
    cdef Entry _c_6040, _c_6060, _c_607a
    cdef Entry _s_60ff, _s_6083, _s_6084, _s_607a, _s_60b0, _s_60b1, _s_6071, _s_60b2
    cdef Entry _s_6065, _s_6085, _s_605a
    cdef public bint _pub_c
    # the published entries' ranges as C arrays, one per PUBLISHED index (P90)
    cdef long long[10] _pub_lo, _pub_hi

    cpdef object _entry(self, int index, int sub)
    cdef Entry _entry_only(self, int index)
    @cython.locals(e=Entry)
    cpdef object _v(self, int index, int sub=*)
    @cython.locals(hits=tuple)
    cpdef tuple _controls(self)
    @cython.locals(c=tuple, hits=tuple)
    cpdef _bind(self)

    @cython.locals(hits=tuple, hit=tuple, e=Entry, k=Py_ssize_t)
    cpdef pub_flush(self)
