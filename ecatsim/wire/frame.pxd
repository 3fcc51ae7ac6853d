# The compiled core's declarations for frame.py (Cython, pure-Python mode): the frame
# header helpers as C calls for the responder (responder.pyx cimports them), so the
# daemon's Python path and the responder share one source. Decisions P2, P9.

cimport cython


@cython.locals(etype="long long")
cpdef long long ecat_offset(const unsigned char[:] buf, long long n, bint ethernet) except? -2
cpdef void mark_processed(unsigned char[:] buf) except *

cdef long long ETHERTYPE_ECAT, ETHERTYPE_VLAN, ETH_HEADER_LEN, VLAN_TAG_LEN, ECAT_HEADER_LEN
