/* Compiled steady cycle of the TMC8670 drive (optional): what Drive.outputs_applied()
 * followed by Drive.update_inputs() do at one instant, for the case that dominates a
 * running bus, and nothing else:
 *   PDS state Operation enabled, AL state OP, mode csp, csv or cst (6060h unchanged), a
 *   controlword that commands nothing new there, no fault, no tracer, the compiled servo
 *   loop in use, and a servo run that does not stop early (an encoder index pulse wired
 *   to a latch input is such a stop: that cycle runs in Python).
 *
 * step(fast, now_ns, outputs) -> bool
 *   fast:    the tuple Drive.compiled_step() builds (stable references only);
 *   outputs: new RxPDO values were written into the OD (outputs_applied runs first).
 *   True:    done, exactly as the Python methods would have done it;
 *   False:   a precondition does not hold; nothing was changed, call the Python methods.
 *
 * All results are computed in locals and written back only at the end, so a servo run
 * that would stop early (following error, overcurrent) changes nothing here: Python then
 * runs it from the same state and handles the stop. tests/unit/slave/
 * test_cycle_compiled.py compares both paths.
 *
 * Ref: ecatsim/device/drive.py (advance, _steady_demand, outputs_applied, _controlword,
 * _publish); TMC8670 Tables 77, 80-83; CiA 402-2 §8 (FSA), §12.6-12.8 (csp, csv, cst);
 * docs/decisions.md P5.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "../_attr.h"
#include "_servo_loop.h"

/* Modes of operation (6060h) and the MODES tuple of drive.py. */
enum { PP = 1, PV = 3, HM = 6, CSP = 8, CSV = 9, CST = 10 };
/* cia402.Command */
enum { C_NONE = 0, C_SHUTDOWN = 1, C_SWITCH_ON = 2, C_SWITCH_ON_ENABLE = 3,
       C_DISABLE_VOLTAGE = 4, C_QUICK_STOP = 5, C_FAULT_RESET = 6 };
/* Statusword bits (drive.py SW_*; STATUS_BITS[OPERATION_ENABLED] = 0x0027). */
#define SW_OPERATION_ENABLED 0x0027
#define SW_VOLTAGE 0x0010
#define SW_REMOTE 0x0200
#define SW_INTERNAL_LIMIT 0x0800
#define SW_OMS12 0x1000
#define SW_MOTOR_ACTIVE 0x4000
#define SW_DIRECTION 0x8000
#define MAX_SUBSTEPS 200000
#define N_SNAPSHOT 11
#define N_PUBLISHED 10
/* index in SNAPSHOT (drive.py) */
enum { Q_60FF, Q_6083, Q_6084, Q_607A, Q_60B0, Q_60B1, Q_6071, Q_60B2, Q_6065, Q_6085,
       Q_605A };

/* fast tuple layout (Drive.compiled_step) */
enum { F_DRIVE, F_SERVO, F_6040, F_6060, F_607A, F_SNAPSHOT, F_PUBLISHED, F_OE, F_AL_OP,
       F_SUBSTEP_NS, F_PPR, F_LEN };

static PyObject *s_tracer, *s_index_output, *s_state, *s_al_state, *s_mode, *s_t_ns,
    *s_active_faults, *s_compiled, *s_id_ref_ma, *s_id_ma, *s_prev_cw, *s_value,
    *s_angle, *s_omega, *s_iq_ma, *s_iq_integ, *s_integ, *s_iq_ref_ma, *s_loop_params,
    *s_overcurrent_ma, *s_v_ff_rpm, *s_p_demand, *s_v_demand_rpm, *s_last_target,
    *s_last_t_ns, *s_i_limit_ma, *s_fault_code, *s_q[N_SNAPSHOT];

static const char *const Q_NAMES[N_SNAPSHOT] = {
    "q_60ff", "q_6083", "q_6084", "q_607a", "q_60b0", "q_60b1",
    "q_6071", "q_60b2", "q_6065", "q_6085", "q_605a",
};

/* Drive._v: an entry's value if it is an int, else 0 (entry None: 0). -1 on error, 1 if the
 * value does not fit a long long (the caller falls back). */
static int entry_int(PyObject *entry, long long *out)
{
    *out = 0;
    if (entry == Py_None)
        return 0;
    PyObject *v = get_attr(entry, s_value);
    if (v == NULL)
        return -1;
    int rc = 0;
    if (PyLong_Check(v)) {
        int over = 0;
        *out = PyLong_AsLongLongAndOverflow(v, &over);
        if (*out == -1 && PyErr_Occurred())
            rc = -1;
        else if (over)
            rc = 1;
    }
    Py_DECREF(v);
    return rc;
}

static int get_double(PyObject *o, PyObject *name, double *out)
{
    PyObject *v = get_attr(o, name);
    if (v == NULL)
        return -1;
    *out = PyFloat_AsDouble(v);
    Py_DECREF(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* An int attribute; 1 if it does not fit a long long. */
static int get_ll(PyObject *o, PyObject *name, long long *out)
{
    PyObject *v = get_attr(o, name);
    if (v == NULL)
        return -1;
    int over = 0;
    *out = PyLong_AsLongLongAndOverflow(v, &over);
    Py_DECREF(v);
    if (*out == -1 && PyErr_Occurred())
        return -1;
    return over ? 1 : 0;
}

static int set_double(PyObject *o, PyObject *name, double x)
{
    PyObject *v = PyFloat_FromDouble(x);
    if (v == NULL)
        return -1;
    int rc = set_attr(o, name, v);
    Py_DECREF(v);
    return rc;
}

/* cia402.decode */
static int decode(long long cw, long long prev)
{
    if ((cw & 0x80) && !(prev & 0x80))
        return C_FAULT_RESET;
    if (cw & 0x80)
        return C_NONE;
    long long low = cw & 0x0F;
    if (!(low & 0x02))
        return C_DISABLE_VOLTAGE;
    if (!(low & 0x04))
        return C_QUICK_STOP;
    if ((low & 0x07) == 0x06)
        return C_SHUTDOWN;
    if (low == 0x07)
        return C_SWITCH_ON;
    return C_SWITCH_ON_ENABLE;
}

static int is_mode(long long m)
{
    return m == 0 || m == PP || m == PV || m == HM || m == CSP || m == CSV || m == CST;
}

/* Python's round(x) for a float (half to even); 0 if x does not fit a long long. */
static int round_ll(double x, long long *out)
{
    if (!isfinite(x) || fabs(x) > 9.0e18)
        return 0;
    *out = (long long)nearbyint(x);
    return 1;
}

static PyObject *step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 3 || !PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != F_LEN) {
        PyErr_SetString(PyExc_TypeError, "step(fast, now_ns, outputs): fast from Drive");
        return NULL;
    }
    PyObject *fast = args[0], *now_obj = args[1];
    int outputs = PyObject_IsTrue(args[2]);
    if (outputs < 0)
        return NULL;
#define ITEM(k) PyTuple_GET_ITEM(fast, k)
    PyObject *drive = ITEM(F_DRIVE), *servo = ITEM(F_SERVO);
    int over = 0;
    long long now = PyLong_AsLongLongAndOverflow(now_obj, &over);
    if (now == -1 && PyErr_Occurred())
        return NULL;
    if (over)
        Py_RETURN_FALSE;

    /* ---- preconditions: read only */
    PyObject *o;
    o = get_attr(drive, s_tracer);
    if (o == NULL)
        return NULL;
    int tracer = o != Py_None;
    Py_DECREF(o);
    o = get_attr(drive, s_index_output);
    if (o == NULL)
        return NULL;
    int index_out = o != Py_None;
    Py_DECREF(o);
    if (tracer)
        Py_RETURN_FALSE;
    o = get_attr(drive, s_state);
    if (o == NULL)
        return NULL;
    int enabled = o == ITEM(F_OE);
    Py_DECREF(o);
    o = get_attr(drive, s_al_state);
    if (o == NULL)
        return NULL;
    int al_op = o == ITEM(F_AL_OP);
    Py_DECREF(o);
    if (!enabled || !al_op)
        Py_RETURN_FALSE;
    o = get_attr(drive, s_active_faults);
    if (o == NULL)
        return NULL;
    Py_ssize_t faults = PyObject_Size(o);
    Py_DECREF(o);
    if (faults != 0)
        return faults < 0 ? NULL : (Py_INCREF(Py_False), Py_False);
    long long mode, t_ns, prev_cw, fault_code;
    int rc;
    if ((rc = get_ll(drive, s_mode, &mode)) != 0)
        return rc < 0 ? NULL : (Py_INCREF(Py_False), Py_False);
    if (mode != CSP && mode != CSV && mode != CST)
        Py_RETURN_FALSE;
    o = get_attr(drive, s_t_ns);
    if (o == NULL)
        return NULL;
    int no_time = o == Py_None;
    Py_DECREF(o);
    if (no_time)
        Py_RETURN_FALSE;
    if ((rc = get_ll(drive, s_t_ns, &t_ns)) != 0 || (rc = get_ll(drive, s_prev_cw, &prev_cw)) != 0 ||
        (rc = get_ll(drive, s_fault_code, &fault_code)) != 0)
        return rc < 0 ? NULL : (Py_INCREF(Py_False), Py_False);
    o = get_attr(servo, s_compiled);
    if (o == NULL)
        return NULL;
    int servo_compiled = PyObject_IsTrue(o);
    Py_DECREF(o);
    if (servo_compiled < 0)
        return NULL;
    double id_ref, id_ma;
    if (get_double(servo, s_id_ref_ma, &id_ref) < 0 || get_double(servo, s_id_ma, &id_ma) < 0)
        return NULL;
    if (!servo_compiled || !(id_ref == 0.0 && id_ma == 0.0))
        Py_RETURN_FALSE; /* the flux axis carries current: the Python loop runs */
    long long cw = 0, od_mode = 0, target_607a = 0;
    if (outputs) {
        if ((rc = entry_int(ITEM(F_6040), &cw)) != 0 || (rc = entry_int(ITEM(F_6060), &od_mode)) != 0 ||
            (rc = entry_int(ITEM(F_607A), &target_607a)) != 0)
            return rc < 0 ? NULL : (Py_INCREF(Py_False), Py_False);
        if (od_mode != mode && is_mode(od_mode))
            Py_RETURN_FALSE; /* a mode change */
        int cmd = decode(cw, prev_cw);
        if (cmd != C_SWITCH_ON_ENABLE && cmd != C_NONE && cmd != C_FAULT_RESET)
            Py_RETURN_FALSE; /* a PDS transition */
    }
    long long substep_ns = PyLong_AsLongLong(ITEM(F_SUBSTEP_NS));
    long long ppr_i = PyLong_AsLongLong(ITEM(F_PPR));
    if (PyErr_Occurred())
        return NULL;
    const double ppr = (double)ppr_i;

    /* ---- advance(now): the servo on fixed substeps, in locals */
    double p_demand, v_demand, v_ff;
    if (get_double(drive, s_p_demand, &p_demand) < 0 || get_double(drive, s_v_demand_rpm, &v_demand) < 0 ||
        get_double(drive, s_v_ff_rpm, &v_ff) < 0)
        return NULL;
    double st[N_STATE];
    PyObject *const snames[N_STATE] = {s_angle, s_omega, s_iq_ma, s_iq_integ, s_integ, s_iq_ref_ma};
    for (int i = 0; i < N_STATE; i++)
        if (get_double(servo, snames[i], &st[i]) < 0)
            return NULL;
    long long diff = now - t_ns;
    long long n = diff < substep_ns ? 0 : diff / substep_ns;
    if (n > MAX_SUBSTEPS)
        Py_RETURN_FALSE;
    long long q[N_SNAPSHOT];
    if (n > 0) {
        PyObject *snap = ITEM(F_SNAPSHOT);
        for (int i = 0; i < N_SNAPSHOT; i++)
            if ((rc = entry_int(PyTuple_GET_ITEM(snap, i), &q[i])) != 0)
                return rc < 0 ? NULL : (Py_INCREF(Py_False), Py_False);
        long kind;
        double ref, ff = 0.0, window = 0.0;
        if (mode == CSP) {
            p_demand = (double)(q[Q_607A] + q[Q_60B0]);
            kind = POSITION;
            ref = p_demand;
            ff = v_ff;
            window = q[Q_6065] == 0xFFFFFFFFLL ? 0.0 : (double)q[Q_6065];
        } else if (mode == CSV) {
            v_demand = (double)(q[Q_60FF] + q[Q_60B1]);
            kind = VELOCITY;
            ref = v_demand;
        } else {
            kind = TORQUE;
            ref = (double)(q[Q_6071] + q[Q_60B2]);
        }
        double i_trip;
        if (get_double(drive, s_overcurrent_ma, &i_trip) < 0)
            return NULL;
        PyObject *params = PyObject_CallMethodNoArgs(servo, s_loop_params);
        if (params == NULL)
            return NULL;
        double p[N_PARAMS];
        int bad = !PyTuple_Check(params) || PyTuple_GET_SIZE(params) != N_PARAMS;
        for (int i = 0; !bad && i < N_PARAMS; i++) {
            p[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(params, i));
            if (p[i] == -1.0 && PyErr_Occurred())
                bad = 1;
        }
        Py_DECREF(params);
        if (bad) {
            if (!PyErr_Occurred())
                PyErr_SetString(PyExc_TypeError, "Servo._loop_params(): 17 floats expected");
            return NULL;
        }
        int why = STOP_NONE;
        long done = servo_loop((long)n, kind, ref, ff, window, i_trip, index_out, st, p, &why);
        if (why != STOP_NONE || done != n)
            Py_RETURN_FALSE; /* it stops early (following error, overcurrent, the encoder's
                              * index pulse): Python runs it and acts on why */
        if (mode != CSP)
            p_demand = st[0] / TWO_PI * ppr; /* follows the actual */
        t_ns += n * substep_ns;
    }

    /* ---- outputs_applied after advance: csp velocity feed-forward, controlword */
    double last_target = 0.0;
    int new_ff = 0, new_target = 0;
    if (outputs && mode == CSP) {
        double target = (double)target_607a;
        PyObject *lt = get_attr(drive, s_last_target);
        if (lt == NULL)
            return NULL;
        PyObject *ltn = get_attr(drive, s_last_t_ns);
        if (ltn == NULL) {
            Py_DECREF(lt);
            return NULL;
        }
        if (lt != Py_None && ltn != Py_None) {
            double prev_target = PyFloat_AsDouble(lt);
            long long prev_t = PyLong_AsLongLongAndOverflow(ltn, &over);
            if (PyErr_Occurred() || over) {
                Py_DECREF(lt);
                Py_DECREF(ltn);
                if (PyErr_Occurred())
                    return NULL;
                Py_RETURN_FALSE;
            }
            double dt = (double)(now - prev_t) * 1e-9;
            if (dt > 0) {
                v_ff = (target - prev_target) / dt * 60.0 / ppr;
                new_ff = 1;
            }
        }
        Py_DECREF(lt);
        Py_DECREF(ltn);
        last_target = target;
        new_target = 1;
    }

    /* ---- _publish: statusword and actual values */
    const double rpm_unit = TWO_PI / 60.0;
    double rpm = st[1] / rpm_unit;
    double counts = floor(st[0] / TWO_PI * ppr);
    if (!isfinite(counts) || fabs(counts) > 9.0e18)
        Py_RETURN_FALSE;
    long long pos = (long long)counts;
    double i_limit;
    if (get_double(servo, s_i_limit_ma, &i_limit) < 0)
        return NULL;
    long long sw = SW_OPERATION_ENABLED | SW_VOLTAGE | SW_REMOTE | SW_OMS12;
    if (fabs(st[5]) >= i_limit - 1e-6)
        sw |= SW_INTERNAL_LIMIT;
    if (fabs(rpm) >= 1.0)
        sw |= SW_MOTOR_ACTIVE;
    if (rpm < -1.0)
        sw |= SW_DIRECTION;
    long long values[N_PUBLISHED];
    values[0] = sw;
    values[1] = mode;
    values[2] = pos;
    values[9] = fault_code;
    if (!round_ll(rpm, &values[3]) || !round_ll(p_demand, &values[4]) ||
        !round_ll(v_demand, &values[5]) || !round_ll(st[2], &values[6]) ||
        !round_ll(st[5], &values[7]) || !round_ll(p_demand - (double)pos, &values[8]))
        Py_RETURN_FALSE;

    /* ---- commit */
    for (int i = 0; i < N_STATE; i++)
        if (set_double(servo, snames[i], st[i]) < 0)
            return NULL;
    if (n > 0) {
        for (int i = 0; i < N_SNAPSHOT; i++)
            if (set_long(drive, s_q[i], q[i]) < 0)
                return NULL;
        if (set_long(drive, s_t_ns, t_ns) < 0)
            return NULL;
        if (mode == CSV && set_double(drive, s_v_demand_rpm, v_demand) < 0)
            return NULL;
        if (set_double(drive, s_p_demand, p_demand) < 0)
            return NULL;
    }
    if (new_ff && set_double(drive, s_v_ff_rpm, v_ff) < 0)
        return NULL;
    if (new_target) {
        if (set_double(drive, s_last_target, last_target) < 0 ||
            set_attr(drive, s_last_t_ns, now_obj) < 0)
            return NULL;
    }
    if (outputs && set_long(drive, s_prev_cw, cw) < 0)
        return NULL;
    PyObject *pub = ITEM(F_PUBLISHED);
    for (int i = 0; i < N_PUBLISHED; i++) {
        PyObject *hit = PyTuple_GET_ITEM(pub, i);
        if (hit == Py_None)
            continue;
        long long lo, hi, v = values[i];
        int olo = 0, ohi = 0;
        lo = PyLong_AsLongLongAndOverflow(PyTuple_GET_ITEM(hit, 1), &olo);
        hi = PyLong_AsLongLongAndOverflow(PyTuple_GET_ITEM(hit, 2), &ohi);
        if (PyErr_Occurred())
            return NULL;
        if (!olo && v < lo)
            v = lo;
        else if (!ohi && v > hi)
            v = hi;
        if (set_long(PyTuple_GET_ITEM(hit, 0), s_value, v) < 0)
            return NULL;
    }
#undef ITEM
    Py_RETURN_TRUE;
}

static PyObject *constants(PyObject *self, PyObject *unused)
{
    (void)self;
    (void)unused;
    return Py_BuildValue("{sisisisisisisisisisi}", "SW_VOLTAGE", SW_VOLTAGE, "SW_REMOTE",
                         SW_REMOTE, "SW_INTERNAL_LIMIT", SW_INTERNAL_LIMIT, "SW_OMS12",
                         SW_OMS12, "SW_MOTOR_ACTIVE", SW_MOTOR_ACTIVE, "SW_DIRECTION",
                         SW_DIRECTION, "SW_OPERATION_ENABLED", SW_OPERATION_ENABLED, "CSP",
                         CSP, "CSV", CSV, "CST", CST);
}

static PyMethodDef methods[] = {
    {"step", (PyCFunction)(void (*)(void))step, METH_FASTCALL,
     "step(fast, now_ns, outputs) -> bool: the drive's steady cycle, or False."},
    {"constants", constants, METH_NOARGS, "The constants compiled in (for tests)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_drive", "Compiled steady cycle of the TMC8670 drive.", -1,
    methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__drive(void)
{
    static const Name names[] = {
        {&s_tracer, "tracer"}, {&s_index_output, "index_output"}, {&s_state, "state"},
        {&s_al_state, "al_state"}, {&s_mode, "mode"}, {&s_t_ns, "t_ns"},
        {&s_active_faults, "active_faults"}, {&s_compiled, "compiled"},
        {&s_id_ref_ma, "id_ref_ma"}, {&s_id_ma, "id_ma"}, {&s_prev_cw, "prev_cw"},
        {&s_value, "value"}, {&s_angle, "angle"}, {&s_omega, "omega"}, {&s_iq_ma, "iq_ma"},
        {&s_iq_integ, "iq_integ"}, {&s_integ, "integ"}, {&s_iq_ref_ma, "iq_ref_ma"},
        {&s_loop_params, "_loop_params"}, {&s_overcurrent_ma, "overcurrent_ma"},
        {&s_v_ff_rpm, "v_ff_rpm"}, {&s_p_demand, "p_demand"},
        {&s_v_demand_rpm, "v_demand_rpm"}, {&s_last_target, "last_target"},
        {&s_last_t_ns, "last_t_ns"}, {&s_i_limit_ma, "i_limit_ma"},
        {&s_fault_code, "fault_code"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return NULL;
    for (int i = 0; i < N_SNAPSHOT; i++) {
        s_q[i] = PyUnicode_InternFromString(Q_NAMES[i]);
        if (s_q[i] == NULL)
            return NULL;
    }
    return PyModule_Create(&module);
}
