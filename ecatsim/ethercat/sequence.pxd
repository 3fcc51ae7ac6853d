# The compiled core's declarations for sequence.py (Cython, pure-Python mode): the
# per-frame sequence's calls as C calls for the responder (responder.pyx cimports it).
# sequence.py stays the one source of the behaviour. Decisions P2, P21.
cimport cython
# int64_t, not long long, for a final type's method with an exception value (P17)
from libc.stdint cimport int64_t

from ecatsim.ethercat.recorder cimport FrameRecorder
from ecatsim.ethercat.segment cimport Segment
# the frame helpers as C calls (imported by sequence.py as Python names: P59)
from ecatsim.wire.frame cimport ecat_offset, mark_processed

cdef long long _NOT_ECAT, _DROPPED, _REPLY


@cython.final
cdef class FrameSequence:
    cdef public Segment segment
    cdef public FrameRecorder recorder
    cdef public bint ethernet
    cdef public long long off
    cdef bytearray _buf
    cdef unsigned char[:] _view

    @cython.locals(view="unsigned char[:]", off="long long", seg=Segment)
    cpdef int64_t arrive(self, bytearray buf, long long n, long long t_rx,
                         long long entry=*) except -1
    cpdef void after(self) except *
    cpdef void service(self, long long t) except *
    cpdef void release(self) except *
