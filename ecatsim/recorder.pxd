# The compiled core's declarations for recorder.py (Cython, pure-Python mode): the ring's
# state as typed fields, so the compiled responder records each frame (next_slot, a copy,
# commit) with C calls. Decisions P2, P9.
cimport cython

cdef long long SLOT


@cython.final
cdef class FrameRecorder:
    cdef public long long depth
    cdef public list _slots
    cdef public bytearray _lens
    cdef public long long _next

    cpdef void record(self, object buf, long long n) except *
    cpdef bytearray next_slot(self)
    @cython.locals(i="long long")
    cpdef void commit(self, long long n) except *
