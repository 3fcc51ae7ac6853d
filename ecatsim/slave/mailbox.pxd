# The compiled core's declarations for mailbox.py (Cython, pure-Python mode): the mailbox
# engine as a typed class, so the firmware asks it in C at every service whether replies
# wait (decision P41), and the engine reaches the ESC through the typed PDI face only.
# mailbox.py stays the one source of the behaviour. Decisions P2, P13.
cimport cython

from ecatsim.esc.pdi cimport Pdi



@cython.final
cdef class MailboxEngine:
    cdef public Pdi pdi
    cdef public dict handlers
    cdef public object accept
    cdef public object out
    cdef public list sources
    cdef public long long _turn
    cdef public object held
    cdef public object last_sent
    cdef public long long counter, last_in_counter
    cdef public bint repeat_ack
    cdef public long long errors
    cdef public long long drop_next
    cdef public object error_next
    cdef public long long stale_counter_next
    cdef public object log

    cpdef bint queued(self) except -1
    cpdef bint pending(self) except -1
