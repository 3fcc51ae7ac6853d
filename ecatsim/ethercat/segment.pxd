# The compiled core's declarations for segment.py (Cython, pure-Python mode): the
# segment's state as typed fields and the frame walk's locals as C integers. segment.py
# stays the one source of the behaviour; this file only gives types. Decisions P2, P13.
cimport cython

from ecatsim.esc.core cimport Esc, FrameContext
from ecatsim.esc.dc cimport DcUnit


cdef long long NOP, APRD, APWR, APRW, FPRD, FPWR, FPRW, BRD, BWR, BRW, LRD, LWR, LRW, ARMW, FRMW
cdef long long CIRCULATING, LEN_MASK, MORE_FOLLOWS, _DC_SYSTEM_TIME, NO_DEADLINE, MAX_SYNC0_CATCHUP
cdef long long PROBE_NS


cdef class Segment:
    cdef public bytearray _dc_after, _dc_before
    cdef public long long _dc_pending, _dc_reach, _dc_reader
    cdef public long long _next_sync, _pulse_hint
    cdef public list _sync_escs
    cdef public dict addr_map
    cdef public object awake
    cdef public long long bad_frames
    cdef public object clock
    cdef public bint compiled
    cdef public FrameContext ctx
    cdef public list escs, firmware, logical
    cdef bytearray _frame
    cdef public long long _frmw_adp, _frmw_reader
    cdef public tuple _frmw_readers
    cdef unsigned char[:] _frame_view
    cdef public long long frames
    cdef public long long irq
    cdef public object persist
    cdef public bint port0_closed
    cdef public long long reach
    cdef public bint reply_first
    cdef public long long sync0_late_ns, sync0_ticks
    cdef public object frame_waiting
    cdef public long long yielded, probe_ns, resume_pos
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
                   ado="long long", lad="long long", esc=Esc,
                   k="long long", i="long long", irq="long long", wkc="long long",
                   readers=tuple, src=bytes, incoming=bytes)
    cpdef void _walk(self, bytearray buf, long long p) except *

    @cython.locals(n="long long", reader="long long", reach="long long", i="long long",
                   escs=list, esc=Esc, before=bytes, after=bytes)
    cpdef void after_reply(self) except *
    @cython.locals(esc=Esc, objs=list, ranges=list, mem=bytearray)
    cpdef tuple hot_lines(self)
    cpdef void pulses_due(self, long long t) except *
    cpdef void service(self, object now_ns=*) except *
    @cython.locals(ctx=FrameContext, esc=Esc, d="long long", look="long long", pos="long long")
    cpdef void service_at(self, long long t) except *
    @cython.locals(best="long long")
    cpdef object next_deadline(self)
    @cython.locals(best="long long", d="long long", e=Esc)
    cpdef long long next_deadline_ns(self) except? -1
    @cython.locals(ctx=FrameContext, esc=Esc, dc=DcUnit, k="long long", nxt="long long",
                   d="long long", d1="long long")
    cpdef void sync_until(self, long long t) except *
