# The compiled core's declarations for recorder.py (Cython, pure-Python mode): the ring's
# state as typed fields, so the per-frame sequence (sequence.py) records each frame with a
# C call. Decisions P2, P21.
cimport cython

cdef long long SLOT


@cython.final
cdef class FrameRecorder:
    cdef public long long depth
    cdef public bytearray _ring
    cdef unsigned char[:] _view
    cdef public bytearray _lens
    cdef public long long _next

    @cython.locals(i="long long", base="long long", ring="unsigned char[:]")
    cpdef void record(self, const unsigned char[:] buf, long long n) except *
