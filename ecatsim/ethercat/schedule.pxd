# The compiled core's declarations for schedule.py (Cython, pure-Python mode): the work
# after the replies as C calls and its state as typed fields. schedule.py stays the one
# source of the behaviour. Decisions P2, P12, P19.
cimport cython

from ecatsim.esc.context cimport FrameContext
from ecatsim.esc.core cimport Esc
from ecatsim.esc.dc cimport DcUnit
from ecatsim.slave.firmware cimport Firmware
# time.monotonic_ns() in schedule.py as Cython's C function over the interpreter's own
# monotonic clock (the one Python's time.monotonic_ns() reads): one C call and no int
# object per look after a slave's SYNC0 work on the daemon's link (P30; decision P67)
from cpython cimport time

cdef long long NO_DEADLINE, MAX_SYNC0_CATCHUP, PULSE_HINT_MARGIN_NS, PROBE_NS


cdef class Schedule:
    cdef public long long _next_sync, _pulse_hint
    cdef public list _sync_escs
    cdef public object awake
    cdef public FrameContext ctx
    cdef public list escs, firmware, deferred
    cdef public object frame_waiting, now_ns
    cdef public object persist
    cdef public object held_logs, write_logs
    cdef public long long probe_ns, resume_pos, yielded
    cdef public long long sync0_late_ns, sync0_ticks, sync0_deferred, sync0_merged

    @cython.locals(ctx=FrameContext, esc=Esc, d="long long", look="long long", pos="long long")
    cpdef void service_at(self, long long t) except *
    cpdef void pulses_due(self, long long t) except *
    @cython.locals(ctx=FrameContext, esc=Esc, dc=DcUnit, k="long long", nxt="long long",
                   d="long long", d1="long long", cfw=Firmware, defer=bint, look="long long",
                   waiting=bint, ran=bint, link=bint)
    cpdef void sync_until(self, long long t, bint frame_first=*) except *
    @cython.locals(lst=list, fw=Firmware, look="long long", ctx=FrameContext, now="long long",
                   i=Py_ssize_t)
    cpdef bint run_deferred(self) except *
    @cython.locals(now="long long")
    cpdef void pulses_meanwhile(self) except *
    cpdef bint pulses_and_their_work(self) except *
    @cython.locals(best="long long")
    cpdef object next_deadline(self)
    @cython.locals(best="long long", w="long long")
    cpdef long long next_deadline_ns(self) except? -1
    @cython.locals(w="long long", d="long long", e=Esc)
    cdef long long _wd_scan(self) noexcept
