# The compiled core's declarations for servo.py (Cython, pure-Python mode): the servo's
# state as typed fields and the substep loop's locals as C doubles. servo.py stays the one
# source of the behaviour; this file only gives types. Decision P2.
cimport cython
# C's libm as _libm: servo.py's second name for math, for copysign in _same (a C call)
cimport libc.math as _libm


cdef double _TWO_PI, _RPM
cdef int _TORQUE, _POSITION, _STOP_NONE, _STOP_FOLLOWING, _STOP_OVERCURRENT, _STOP_INDEX


cdef class Gains:
    cdef public double cur_kp, cur_ki, flux_kp, flux_ki, vel_kp, vel_ki, pos_kp


@cython.final
cdef class Servo:
    cdef public object p
    cdef public double _dt, _ppr, _kt, _load, _viscous, _coulomb, _inertia, _vmax_v
    cdef public double _resistance
    cdef public int stopped
    cdef public Gains gains
    cdef public double angle
    cdef public double omega
    cdef public double iq_ma
    cdef public double iq_ref_ma
    cdef public double id_ma
    cdef public double id_ref_ma
    cdef public double iq_integ
    cdef public double id_integ
    cdef public double integ
    cdef public double decay
    cdef public double i_limit_ma
    cdef public double vel_limit_rpm
    cdef public bint fast_hold

    cpdef object read_counts(self)
    cpdef double floor_counts(self) except? -1.0
    # -1.0 as its error value (a test of the thread's error state only then; P83)
    cpdef double read_rpm(self) except? -1.0

    cpdef tuple run(self, long n, int kind, double ref, double v_ff_rpm=*, double window=*,
                    double i_trip_ma=*, bint index=*)
    @cython.locals(
        dt=double, ppr=double, kt=double, load=double, viscous=double, coulomb=double,
        inertia=double, vmax_v=double, resistance=double, decay=double, lim=double,
        vlim=double, vel_kp=double, vel_ki=double, pos_kp=double, cur_kp=double,
        cur_ki=double, angle=double, omega=double, iq=double, iq_integ=double, integ=double,
        iq_ref=double, flux=bint, done=long, why=int, out=double, err_p=double, v_ref=double,
        err=double, emf=double, err_a=double, v=double, torque=double, drive=double,
        new=double, rev=double, rev_known=bint, now=double, q=double, rev_hi=double,
        rev_cmp=bint, torque_kind=int, position_kind=int, id_ma=double, id_integ=double,
        hold=bint,
        g=Gains,
    )
    cpdef long _run(self, long n, int kind, double ref, double v_ff_rpm, double window,
                    double i_trip_ma, bint index) except? -1


# cpdef: the tests call it in both cores (a static C function to _run, which gcc inlines)
cpdef bint _same(double a, double b) noexcept


@cython.locals(k="long long")
cdef inline double _floor(double x) except? -1.0
