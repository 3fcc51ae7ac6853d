# The compiled core's declarations for drive.py (Cython, pure-Python mode): the drive's
# state as typed fields, the servo as a typed Servo (its loop called directly), and the
# locals of the steady cycle's methods. drive.py stays the one source of the behaviour;
# this file only gives types. Decision P2.
cimport cython

from ecatsim.device.servo cimport Servo
cimport ecatsim.device.cia402 as cia402
from ecatsim.slave.od cimport Entry
from ecatsim.device.drive_od cimport DriveOd


# the statusword bits as C constants (drive.py uses them only within itself)
cdef long long SW_VOLTAGE, SW_WARNING, SW_REMOTE, SW_TARGET_REACHED, SW_INTERNAL_LIMIT
cdef long long SW_OMS12, SW_OMS13, SW_MOTOR_ACTIVE, SW_DIRECTION
# the modes as C constants (PP... stay Python ints for other modules)
cdef long long _PP, _PV, _HM, _CSP, _CSV, _CST
cdef int _STOP_NONE, _STOP_FOLLOWING, _STOP_OVERCURRENT, _STOP_INDEX
cdef long long _NO_WINDOW
cdef int _TORQUE, _VELOCITY, _POSITION
# the enum members the cycle compares by identity, as C globals (no module dict lookup)
cdef object _OE, _QSA, _FRA, _FAULT, _SOD, _SO, _NRTSO, _AL_OP, _FAULT_RESET
cdef object _SWITCH_ON_ENABLE
cdef tuple _STATUS_BITS


cdef object _round(double x)
@cython.locals(k="long long", f=double)
# inline (Cython warns that a declaration should not say so; it makes them C inline
# functions, which the per-cycle callers absorb: decision P51)
cdef inline long long _round_c(double x) noexcept
cdef inline bint _small(double x) noexcept
@cython.locals(k="long long")
cdef inline long long _trunc_c(double x) noexcept


cdef inline bint _powered(object st) noexcept
cdef inline bint _no_voltage(object st) noexcept


cdef inline long long _int_of(Entry e) except? -1


cdef class Drive(DriveOd):
    cdef public long long q_60ff, q_6083, q_6084, q_607a, q_60b0, q_60b1, q_6071, q_60b2
    cdef public long long q_6065, q_6085, q_605a
    cdef bint _snap_all
    cdef int _d_kind
    cdef double _d_ref, _d_vff, _d_window
    cdef public object params
    cdef double _ppr
    cdef public long long substep_ns
    cdef public Servo servo
    cdef public object profile
    cdef public object emcy
    cdef public object emcy_clear
    cdef public object state
    cdef object _sw_state
    cdef long long _sw_bits
    cdef long long _t, _ltn
    cdef double _lt
    cdef bint _t_set, _lt_set, _ltn_set
    cdef public long long prev_cw
    cdef public long long _quiet_cw
    cdef public object _quiet_state
    cdef public long long mode
    cdef object _al_state
    cdef bint _al_op
    cdef public double v_demand_rpm
    cdef public double p_demand
    cdef public double v_ff_rpm
    cdef public bint set_point_ack
    cdef public bint homing_done
    cdef public bint homing_active
    cdef public double home_offset_counts
    cdef public set active_faults
    cdef public long long fault_code
    cdef public set injected
    cdef public double overcurrent_ma
    cdef public object index_output
    cdef public object tracer
    cdef public object log

    @cython.locals(target=double, dt=double, now="long long", then="long long", prev=double,
                   ppr=double)
    cpdef outputs_applied(self, long long now_ns)

    cpdef update_inputs(self, long long now_ns)

    @cython.locals(dt_ns="long long", n="long long", left="long long", t="long long",
                   now="long long", start="long long",
                   done="long long", more="long long", steps="long long", why=int,
                   kind=int, ref=double, v_ff=double, window=double, s=Servo)
    cpdef advance(self, long long now_ns)

    # a C double with -1.0 as its error value: the thread's error state is read only
    # after a -1.0, not after every call (decision P83)
    cpdef double _trip(self) except? -1.0
    cpdef double _window(self) except? -1.0
    @cython.locals(mode="long long")
    cpdef _snapshot(self)
    cpdef _snapshot_all(self)

    @cython.locals(mode="long long", v=double, target=double)
    cpdef bint _steady_demand(self) except -1
    # C fields set from C arguments, nothing that can raise (P83)
    cdef bint _demand(self, int kind, double ref, double v_ff, double window) noexcept

    @cython.locals(cw="long long", mode="long long", prev="long long")
    cpdef _controlword(self)

    @cython.locals(s=Servo, sw="long long", rpm=double, mode="long long", hits=tuple,
                   values=tuple, k=Py_ssize_t, hit=tuple, e=Entry, pos_f=double,
                   pos_c="long long", p_demand=double, err=double, v_demand=double,
                   iq=double, iq_ref=double, si="long long")
    cpdef _publish(self)


# k unsigned: no test for a negative index per array read (decision P60)
@cython.locals(lo="long long", hi="long long")
cdef inline int _put(Drive d, size_t k, long long v) except -1
