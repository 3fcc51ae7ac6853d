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
