# The compiled core's declarations for pdo.py (Cython, pure-Python mode): the process
# image copy of a CoE slave's DC cycle (decoded into and packed from the OD entries) as
# compiled code. pdo.py stays the one source of the behaviour. Decisions P2, P3, P13.
cimport cython

from ecatsim.esc.pdi cimport SmImage
from ecatsim.slave.od cimport Entry


cdef class CycleDevice:
    cdef public long long[::1] pub_values
    cdef public bint pub_pending
    cpdef outputs_applied(self, long long now_ns)
    cpdef update_inputs(self, long long now_ns)
    cpdef pub_flush(self)


@cython.final
cdef class PdoImage(SmImage):
    cdef public object od, rules
    cdef object _device
    cdef CycleDevice _dev
    cdef object _plan
    cdef object _rx_st, _tx_st
    cdef Py_ssize_t _rx_need
    cdef tuple _rx_entries, _tx_entries
    cdef tuple _rx_layout, _tx_layout
    cdef long long[::1] _rx_spec, _tx_spec
    cdef bytearray _tx_buf
    cdef long long[::1] _tx_slot
    cdef long long[::1] _tx_vals
    cdef bint _tx_gaps

    @cython.locals(entries=tuple, values=tuple, i="Py_ssize_t", e=Entry, dev=CycleDevice,
                   layout=tuple, buf=bytes, ba=bytearray)
    cpdef void set_outputs(self, object data, long long now_ns) except *
    # the outputs from a pointer to bytes or to the firmware's latched buffer (P33, P70)
    @cython.locals(entries=tuple, i="Py_ssize_t", e=Entry, spec="long long",
                   off="Py_ssize_t", n="long long", raw="long long", half="long long",
                   byte="long long")
    cdef void _rx_decode(self, const unsigned char* q) except *
    cpdef bytes get_inputs(self, long long now_ns)
    @cython.locals(dev=CycleDevice)
    cpdef void update_inputs(self, long long now_ns) except *
    @cython.locals(entries=tuple, values=list, i="Py_ssize_t", e=Entry, layout=tuple,
                   dev=CycleDevice)
    cpdef bytes pack_inputs(self)
    @cython.locals(out=bytearray, p="unsigned char*")
    cdef object _pack_small(self)
    # the inputs straight into SM3's buffer (Pdi.sm_fill, P71): values checked first, then
    # stored, so a value that does not fit leaves the buffer untouched
    # fill: SmImage's, declared there (a final type cannot redeclare an inherited cpdef);
    # its work on a pointer to the ESC memory:
    @cython.locals(k="long long")
    cdef void _fill_at(self, unsigned char* p, long long base, long long n) noexcept
    @cython.locals(entries=tuple, i="Py_ssize_t", e=Entry, c="long long", spec="long long",
                   n="long long", half="long long", dev=CycleDevice, pending=bint,
                   slot="Py_ssize_t")
    cdef bint _tx_values(self) except -1
    @cython.locals(i="Py_ssize_t", c="long long", spec="long long", off="Py_ssize_t",
                   n="long long")
    cdef void _tx_store(self, unsigned char* p, long long base) noexcept


cpdef long long _c_int(object v) except? -1
