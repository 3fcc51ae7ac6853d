# The compiled core's declarations for prefetch.py (Cython, pure-Python mode): the list
# of lines the responder prefetches, built with typed locals. Decisions P2, P18.
cimport cython

from ecatsim.esc.core cimport Esc
from ecatsim.ethercat.segment cimport Segment


@cython.locals(esc=Esc, objs=list, ranges=list, mem=bytearray)
cpdef tuple hot_lines(Segment seg)
