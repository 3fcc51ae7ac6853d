# The compiled core's declarations for od.py (Cython, pure-Python mode): an OD entry as an
# extension type, so the drive's cycle and the process image copy read and write its value
# as a field, not through Python's generic attribute lookup. od.py stays the one source of
# the behaviour; this file only gives types. Decision P15.


cdef class Entry:
    cdef public object sub, name, dtype, access, pdo, minimum, maximum, default, unit
    cdef public object values, write_states, value, bits, pdo_bits
