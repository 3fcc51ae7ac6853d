# The compiled core's declarations for cia402.py (Cython, pure-Python mode): decode() and
# step() callable in C from the compiled drive (drive.pxd cimports this module). cia402.py
# stays the one source of the behaviour; this file only gives types. Decision P2.

cimport cython


cpdef object decode(long long controlword, long long previous)

@cython.locals(table=tuple, s="long long", c="long long")
cpdef object step(object state, object cmd)
