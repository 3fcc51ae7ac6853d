# The compiled core's declarations for dc.py (Cython, pure-Python mode): the DC unit's
# state as typed fields. The clock's reference, its host time and the SYNC deadlines stay
# Python integers (the arithmetic is modulo 2^64 on unbounded values, as in dc.py); the
# rates are C doubles, computed in the same order as Python (built -ffp-contract=off).
# Decisions P2, P13.
cdef class DcUnit:
    cdef public bytearray mem
    cdef public long long position, hop_ns, turnaround_ns, sync1_countdown
    cdef public double drift_ppm, rate_ppb, spd
    cdef public object moved_ns, t_ref, local_ref, next_sync0, next_sync1

    cpdef object arrival_ns(self, object frame_t_ns)
    cpdef object local_time(self, object t_ns)
    cpdef void _set_rate(self, double rate_ppb) except *
    cpdef object offset(self)
    cpdef object system_time(self, object t_ns)
    cpdef void refresh_system_time(self, object frame_t_ns) except *
    cpdef bint system_time_written(self, object frame_t_ns, object value, long long nbytes) except -1
    cpdef object host_time_of(self, object system_ns)
    cpdef object sync0_deadline(self)
    cpdef bint sync0_pulse(self, object now_ns) except -1
    cpdef void _schedule_sync1(self, object sync0_time, object cycle0) except *
    cpdef object sync1_deadline(self)
    cpdef bint sync1_pulse(self) except -1
    cpdef void _speed_counter_diff(self, long long start) except *
