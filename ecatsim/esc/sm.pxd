# The compiled core's declarations for sm.py (Cython, pure-Python mode): the SyncManager's
# state as typed fields. sm.py stays the one source of the behaviour; this file only
# gives types. Decisions P2, P13.
cimport cython
# int64_t, not long long, for the methods of a final class with an exception value:
# Cython 3.3 writes long long's value there as -1LLLL in pure-Python mode
from libc.stdint cimport int64_t

# the register bits, imported from regs.py: C constants here
cdef long long DC_ECAT_EVENT_TIME, SM_ACT_LATCH_ECAT, SM_CTRL_ECAT_IRQ, SM_CTRL_PDI_IRQ, SM_CTRL_WATCHDOG, SM_DIR_MASK, SM_DIR_WRITE, SM_MODE_MAILBOX, SM_MODE_MASK, SM_ST_BUF_SHIFT, SM_ST_IRQ_READ, SM_ST_IRQ_WRITE, SM_ST_MBX_FULL, SM_ST_READ_OPEN, SM_ST_WRITE_OPEN


cdef class SyncManager


@cython.locals(k="long long")
cdef inline void _copy(unsigned char* dst, long long d, const unsigned char* src, long long s,
                       long long n) noexcept


cdef class SmHost:
    # noexcept: the ESC only moves its event bits (core.pxd, P48)
    cpdef void sm_status_changed(self, SyncManager sm) noexcept
    cpdef void wd_pd_trigger(self) noexcept
    cpdef void sm_event_time(self, long long reg) except *
    cpdef void sm_restart(self, long long n) except *


@cython.final
cdef class SyncManager:
    cdef public SmHost host
    cdef unsigned char[:] mv
    # the ESC memory's bytes (mem, never resized: mv holds its buffer), for the status
    # register and the frame walk's copies (P62)
    cdef unsigned char* mp
    cdef public bytearray mem
    cdef public long long n, status_addr, start, length, control
    cdef public bint active, enabled, locked, mailbox, ecat_side_writes, mbx_full
    cdef public long long w, l, r
    cdef public bint r_open, w_open
    cdef public long long status, mirror, changed, irq_to_ecat, irq_to_pdi

    @cython.locals(to_ecat="long long", to_pdi="long long")
    cpdef void configure(self, long long start, long long length, long long control, bint active,
                         bint locked=*) except *
    # inline and noexcept: the buffer state, the status register through the pointer mp,
    # the ESC's event bits (SmHost.sm_status_changed): nothing here raises (P62)
    @cython.locals(st="long long", mirror="long long", p="unsigned char*")
    cdef inline void _sync(self) noexcept
    @cython.locals(latest="long long")
    cdef inline void _writer_access(self, bint first, bint last) noexcept
    cdef inline void _reader_open(self) noexcept
    cdef inline void _reader_access(self, bint first, bint last) noexcept
    cdef inline long long _base_for_write(self) noexcept
    @cython.locals(b="long long")
    cdef inline long long _base_for_read(self) noexcept
    cpdef bint writer_may(self) noexcept
    cpdef bint reader_may(self) noexcept
    cpdef bint ecat_may_write(self) noexcept
    cpdef bint ecat_may_read(self) noexcept
    cpdef bint pdi_may_write(self) noexcept
    cpdef bint pdi_may_read(self) noexcept
    @cython.locals(first=bint, last=bint, base="long long", mv="unsigned char[:]", k="long long",
                   n="long long", p="unsigned char*")
    cpdef void writer_write(self, long long off, const unsigned char[:] data) except *
    @cython.locals(first=bint, last=bint, base="long long", mv="unsigned char[:]", k="long long",
                   n="long long", p="const unsigned char*")
    cpdef void reader_read(self, long long off, unsigned char[:] out) except *
    @cython.locals(base="long long", end="long long", mem=bytearray, p="const unsigned char*")
    cpdef bytes read_whole(self)
    @cython.locals(base="long long", mem=bytearray, i="long long", n="long long",
                   p="unsigned char*", d="const unsigned char*")
    cpdef void write_whole(self, bytes data) except *
    # the PDI's process data without a bytes object (P70, P71)
    @cython.locals(base="long long", mem=bytearray, k="long long", q="unsigned char*")
    cpdef void read_into(self, bytearray out) except *
    @cython.locals(base="long long")
    cpdef long long whole_base(self, long long n) noexcept
    cpdef void written(self) noexcept
    cpdef void ecat_write(self, long long off, const unsigned char[:] data) except *
    # the frame walk's logical path: one C call per SM access, pointers into the frame (P61)
    @cython.locals(base="long long", last=bint, p="unsigned char*")
    cpdef bint ecat_write_at(self, long long off, bytearray buf, long long pos,
                             long long n) except -1
    @cython.locals(reader=bint, first=bint, last=bint, p="unsigned char*")
    cpdef bint ecat_read_at(self, long long off, bytearray buf, long long pos,
                            long long n) except -1
    cdef void _ecat_checked(self, long long off, bytearray buf, long long pos, long long n,
                            bint write) except *
    @cython.locals(base="long long")
    cpdef void ecat_read(self, long long off, unsigned char[:] out) except *
