# The compiled core's declarations for firmware.py (Cython, pure-Python mode): the
# firmware's state as typed fields and its event service on C integers, reaching the ESC
# through the typed PDI face only (pdi.pxd; tests/unit/test_layering.py checks the
# cimports). firmware.py stays the one source of the behaviour. Decisions P2, P3, P13.
cimport cython

from ecatsim.esc.pdi cimport Pdi
from ecatsim.slave.mailbox cimport MailboxEngine
from ecatsim.slave.pdo cimport PdoImage

# the registers and events, imported through pdi.py: C constants here
cdef long long AL_CONTROL, AL_EVENT_MASK, AL_STATUS, AL_STATUS_CODE, DC_ACTIVATION
cdef long long DC_ACTIVATION_STATUS, DC_SYNC0_STATUS, EV_AL_CONTROL, EV_SM0
cdef long long EV_SM_ACTIVATION, EV_SYNC0, EV_WATCHDOG_PD, WD_STATUS_PD
cdef long long SM_MBX_OUT, SM_MBX_IN, SM_PD_OUT, SM_PD_IN
cdef long long EV_SM1, PD_EVENTS, EVENT_MASK, OP_WAIT_NS
# the AL states the steady cycle compares with: C globals, each test a pointer comparison
# without a lookup in the module's dict (P86)
cdef object _INIT, _SAFEOP, _OP


cdef bint _dc_synchronous(Pdi p) except -1


@cython.final
cdef class Firmware:
    cdef public Pdi pdi
    cdef object _app
    cdef PdoImage _pdo
    cdef public object mailbox
    cdef public MailboxEngine mbx
    cdef public long long event_mask
    cdef public object od, emergency, device, coe
    cdef public bint pd_masked
    cdef public object refuse_next
    cdef public bint outputs_seen
    cdef public long long op_requested_ns
    cdef public long long sync_ns
    cdef public bytearray sync_out
    cdef public bint sync_has_out
    cdef public bint bootstrap_supported
    cdef public object state
    cdef public bint error
    cdef public long long code
    cdef public object log

    @cython.locals(p=Pdi, ev="long long", pd_events="long long", dc=bint, pdo=PdoImage)
    cpdef void service(self, long long now_ns) except *
    @cython.locals(p=Pdi, ev="long long")
    cpdef bint sync0_latch(self, long long now_ns) except *
    # the per-pulse helpers only the firmware calls: an int (0, or -1 with an exception
    # set), so no PyErr_Occurred() test follows each call (P87)
    cdef int _latch(self, Pdi p, long long ev, long long now_ns) except -1
    # the pulse's time as a C integer down to the image's calls, which take one (an int
    # object only for an Application called through Python; decision P60)
    @cython.locals(pdo=PdoImage, now_ns="long long", has_out=bint)
    cpdef void sync0_run(self) except *
    @cython.locals(now_ns="long long", mbx=MailboxEngine, p=Pdi, masked=bint)
    cpdef void run_latched(self) except *
    cdef int _op_wait(self, long long now_ns) except -1
    @cython.locals(pdo=PdoImage)
    cdef int _apply_outputs(self, object out, long long now_ns) except -1
    @cython.locals(want="long long", pending=bint, mbx=MailboxEngine)
    cpdef void service_mailbox(self, long long ev, long long now_ns) except *
    cdef int _outputs_received(self, long long now_ns) except -1
    @cython.locals(pdo=PdoImage, p=Pdi)
    cdef int _write_inputs(self, long long now_ns) except -1
