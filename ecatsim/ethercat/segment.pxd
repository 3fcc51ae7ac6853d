# The compiled core's declarations for segment.py (Cython, pure-Python mode): the
# segment's state as typed fields and the frame walk's locals as C integers. segment.py
# stays the one source of the behaviour; this file only gives types. Decisions P2, P13.
cimport cython

from ecatsim.esc.context cimport FrameContext
from ecatsim.esc.core cimport Esc
from ecatsim.esc.dc cimport DcUnit
from ecatsim.ethercat.logical_index cimport LogicalIndex
from ecatsim.ethercat.schedule cimport Schedule


cdef long long APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW
cdef long long CIRCULATING, LEN_MASK, MORE_FOLLOWS, _DC_SYSTEM_TIME


cdef class Segment:
    cdef public bytearray _dc_after, _dc_before
    cdef public long long _dc_pending, _dc_reach, _dc_reader
    cdef public dict addr_map
    cdef public long long bad_frames
    cdef public object clock
    cdef public bint compiled
    cdef public FrameContext ctx
    cdef public list escs, firmware, logical
    cdef public LogicalIndex logical_index
    cdef public Schedule schedule
    cdef bytearray _frame
    cdef public long long _frmw_adp, _frmw_reader
    cdef public tuple _frmw_readers
    cdef unsigned char[:] _frame_view
    cdef public long long frames
    cdef public long long irq
    cdef public bint port0_closed
    cdef public long long reach
    cdef public bint reply_first
    cdef public long long _cur, _cur_exit, exit
    cdef public bint processed, out_up
    cdef public list chain, routes, wiring

    @cython.locals(ctx=FrameContext, hdr="long long", end="long long", p="long long",
                   lf="long long", q="long long")
    cpdef bint process(self, bytearray buf, long long off, long long n,
                       long long t_ns=*, long long entry=*) except -1
    @cython.locals(reader="long long", n="long long", inc="long long", esc=Esc,
                   before="unsigned char[:]", after="unsigned char[:]")
    cpdef long long _frmw_system_time(self, unsigned char[:] data, long long first,
                                      long long reach) except -1

    @cython.locals(ctx=FrameContext, escs=list, reach="long long", cmd="long long",
                   lf="long long", dlen="long long", d0="long long", w="long long",
                   mv="unsigned char[:]", data="unsigned char[:]", inc="long long",
                   adp="long long",
                   ado="long long", esc=Esc,
                   k="long long", i="long long", irq="long long", wkc="long long",
                   readers=tuple, src=bytes, incoming=bytes)
    cpdef void _walk(self, bytearray buf, long long p) except *

    @cython.locals(n="long long", reader="long long", reach="long long", i="long long",
                   escs=list, esc=Esc, before=bytes, after=bytes)
    cpdef void after_reply(self) except *
    cpdef void service(self, object now_ns=*) except *
    cpdef void service_at(self, long long t) except *
