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
    # the layouts' tables and pointers to their bytes, kept beside them (P89)
    cdef bytearray _rx_tab, _tx_tab
    cdef unsigned char* _rx_tp
    cdef unsigned char* _tx_tp
    cdef bint _tx_slots_on
    cdef Py_ssize_t _tx_top
    cdef bytearray _tx_buf
    cdef unsigned char* _tx_bp

    @cython.locals(entries=tuple, values=tuple, i="Py_ssize_t", e=Entry, dev=CycleDevice,
                   layout=tuple, buf=bytes, ba=bytearray)
    cpdef void set_outputs(self, object data, long long now_ns) except *
    # the outputs from a pointer to bytes or to the firmware's latched buffer (P33, P70)
    @cython.locals(entries=tuple, i="Py_ssize_t", e=Entry, spec="long long",
                   off="Py_ssize_t", n="long long", raw="long long",
                   byte="long long", t="const unsigned char*", j="Py_ssize_t")
    cdef int _rx_decode(self, const unsigned char* q) except -1
    cpdef bytes get_inputs(self, long long now_ns)
    @cython.locals(dev=CycleDevice)
    cpdef void update_inputs(self, long long now_ns) except *
    @cython.locals(entries=tuple, values=list, i="Py_ssize_t", e=Entry, layout=tuple,
                   dev=CycleDevice)
    cpdef bytes pack_inputs(self)
    @cython.locals(out=bytearray, p="unsigned char*")
    cdef object _pack_small(self)
    # fill: SmImage's, declared there (a final type cannot redeclare an inherited cpdef);
    # the inputs encoded into _tx_buf, then copied into SM3's buffer (P71)
    @cython.locals(k="long long")
    cdef void _copy_to(self, unsigned char* dst, long long d, const unsigned char* src,
                       long long n) noexcept
    @cython.locals(entries=tuple, p="unsigned char*", i="Py_ssize_t", e=Entry,
                   c="long long",
                   spec="long long", off="Py_ssize_t", n="long long",
                   dev=CycleDevice,
                   pending=bint, slot="size_t", t="const unsigned char*",
                   j="Py_ssize_t")
    cdef bint _pack_buf(self) except -1


# a layout row's field range by its spec, 0-15 (P95): C arrays, read with no bounds test
cdef long long[16] _SPEC_LO, _SPEC_HI


cpdef long long _c_int(object v) except? -1
