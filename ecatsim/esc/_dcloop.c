/* Compiled DC time loops of an FRMW of 0x0910 (optional, decision P11): the work
 * Segment.after_reply leaves for the writers of the frame's system time, each a physical
 * write of 0x0910 (Esc.ecat_write -> _reg_write -> Esc._ew_dc_system_time ->
 * DcUnit.system_time_written), for every writer in one call.
 *
 * time_loops(seg, hook) -> bool
 *   seg:  the Segment, with an FRMW left pending (_dc_pending: the data length, 4 or 8;
 *         _dc_reader, _dc_reach, _dc_before, _dc_after as Segment._frmw_system_time set
 *         them);
 *   hook: Esc._ew_dc_system_time, the only register hook the write may meet.
 *   True:  every writer's write was done here, and _dc_pending is 0.
 *   False: a precondition does not hold for some writer (an SM window over 0x0910, a
 *          write mask or a hook other than the plain register's); nothing was changed
 *          and the caller runs the Python loop, the reference.
 *
 * The arithmetic is Python's: the DC unit's local clock is piecewise linear in double
 * precision (DcUnit.local_time), its reference kept as an unbounded Python int (here a
 * 128-bit integer), the clock speed and rate as doubles computed in the same order (the
 * module is built with -ffp-contract=off). tests/unit/slave/test_cycle_compiled.py runs
 * both and compares every register, the DC units' state and the timers flag.
 *
 * Ref: TMC8460 §5.50.2 Tables 95-101 (system time, offset, delay, difference, speed
 * counter); ETG.1000.4 §5.4.3 Table 12 (FRMW); docs/decisions.md P7, P11.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "../_attr.h"
#include "_windows.h"

/* ecatsim/esc/regs.py, ecatsim/esc/dc.py (the test checks they agree) */
#define DC_SYSTEM_TIME 0x0910
#define DC_SYSTEM_TIME_LEN 8
#define DC_SYSTEM_TIME_OFFSET 0x0920
#define DC_SYSTEM_TIME_DELAY 0x0928
#define DC_SYSTEM_TIME_DIFF 0x092C
#define DC_SPEED_COUNTER_START 0x0930
#define MOVE_NS 50000
#define FAR_NS 1000000
#define MEM_SIZE 0x10000

typedef __int128 i128;

static PyObject *s_escs, *s_ctx, *s_t_ns, *s_timers_dirty, *s_dc_pending, *s_dc_reader,
    *s_dc_reach, *s_dc_before, *s_dc_after, *s_sm_windows, *s_t, *s_ecat_wmask,
    *s_ecat_w_hooked, *s_ecat_w, *s_mem, *s_dc, *s_wr_s, *s_wr_e, *s_position, *s_hop_ns,
    *s_local_ref, *s_t_ref, *s_spd, *s_rate_ppb, *s_drift_ppm, *s_moved_ns, *two64;

static inline uint64_t rd(const uint8_t *m, long a, int n)
{
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--)
        v = (v << 8) | m[a + i];
    return v;
}

static inline void wr(uint8_t *m, long a, uint64_t v, int n)
{
    for (int i = 0; i < n; i++)
        m[a + i] = (uint8_t)(v >> (8 * i));
}

/* A Python int of any size within +-2^126 as i128; -1 with the exception set. */
static int as_i128(PyObject *v, i128 *out)
{
    int overflow;
    long long x = PyLong_AsLongLongAndOverflow(v, &overflow);
    if (x == -1 && PyErr_Occurred())
        return -1;
    if (!overflow) {
        *out = x;
        return 0;
    }
    /* v = q * 2^64 + r: r from the low 64 bits, q from v >> 64 */
    uint64_t lo = PyLong_AsUnsignedLongLongMask(v);
    PyObject *shift = PyLong_FromLong(64);
    PyObject *hi = shift == NULL ? NULL : PyNumber_Rshift(v, shift);
    Py_XDECREF(shift);
    if (hi == NULL)
        return -1;
    long long q = PyLong_AsLongLongAndOverflow(hi, &overflow);
    Py_DECREF(hi);
    if ((q == -1 && PyErr_Occurred()) || overflow || q > (1LL << 61) || q < -(1LL << 61)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_OverflowError, "DC state out of range");
        return -1;
    }
    *out = (i128)q * ((i128)1 << 64) + (i128)lo;
    return 0;
}

/* i128 -> Python int (new reference). */
static PyObject *from_i128(i128 v)
{
    if (v >= INT64_MIN && v <= INT64_MAX)
        return PyLong_FromLongLong((long long)v);
    i128 q = v >> 64; /* floor */
    uint64_t lo = (uint64_t)v;
    PyObject *qo = PyLong_FromLongLong((long long)q);
    PyObject *lo_o = PyLong_FromUnsignedLongLong(lo);
    PyObject *hi = (qo == NULL) ? NULL : PyNumber_Multiply(qo, two64);
    PyObject *out = (hi == NULL || lo_o == NULL) ? NULL : PyNumber_Add(hi, lo_o);
    Py_XDECREF(qo);
    Py_XDECREF(lo_o);
    Py_XDECREF(hi);
    return out;
}

static int set_obj(PyObject *o, PyObject *name, PyObject *v)
{
    if (v == NULL)
        return -1;
    int rc = set_attr(o, name, v);
    Py_DECREF(v);
    return rc;
}

/* Esc.ecat_write(0x0910, data[:n]) goes the plain register way to the system time hook
 * only: no SM window over it, every bit writable, and the register's one hook (every
 * byte of 0x0910-0x0917 maps to it, called once) is Esc._ew_dc_system_time.
 * 1 yes, 0 no, -1 error. */
static int plain_system_time(PyObject *esc, PyObject *hook, long n)
{
    /* a window over 0x0910: Esc.ecat_write goes to the SM */
    int ok = no_sm_window(esc, s_sm_windows, DC_SYSTEM_TIME, DC_SYSTEM_TIME + n);
    if (ok != 1)
        return ok;
    PyObject *t = get_attr(esc, s_t);
    PyObject *mask = t == NULL ? NULL : get_attr(t, s_ecat_wmask);
    PyObject *hooked = t == NULL ? NULL : get_attr(t, s_ecat_w_hooked);
    PyObject *table = t == NULL ? NULL : get_attr(t, s_ecat_w);
    if (mask == NULL || hooked == NULL || table == NULL) {
        ok = -1;
    } else if (!PyBytes_Check(mask) || !PyBytes_Check(hooked) || !PyTuple_Check(table) ||
               PyBytes_GET_SIZE(mask) < DC_SYSTEM_TIME + n ||
               PyBytes_GET_SIZE(hooked) < DC_SYSTEM_TIME + n ||
               PyTuple_GET_SIZE(table) <= DC_SYSTEM_TIME) {
        ok = 0;
    } else {
        const uint8_t *mk = (const uint8_t *)PyBytes_AS_STRING(mask);
        const uint8_t *hk = (const uint8_t *)PyBytes_AS_STRING(hooked);
        for (long a = DC_SYSTEM_TIME; a < DC_SYSTEM_TIME + n; a++)
            if (mk[a] != 0xFF || hk[a] != 1)
                ok = 0;
        PyObject *entry = PyTuple_GET_ITEM(table, DC_SYSTEM_TIME);
        if (ok && (!PyTuple_Check(entry) || PyTuple_GET_SIZE(entry) != 3 ||
                   PyTuple_GET_ITEM(entry, 0) != hook ||
                   PyLong_AsLong(PyTuple_GET_ITEM(entry, 1)) != DC_SYSTEM_TIME ||
                   PyLong_AsLong(PyTuple_GET_ITEM(entry, 2)) != DC_SYSTEM_TIME_LEN))
            ok = PyErr_Occurred() ? -1 : 0;
    }
    Py_XDECREF(t);
    Py_XDECREF(mask);
    Py_XDECREF(hooked);
    Py_XDECREF(table);
    PyObject *mem = ok == 1 ? get_attr(esc, s_mem) : NULL;
    if (ok == 1 && (mem == NULL || !PyByteArray_Check(mem) || PyByteArray_GET_SIZE(mem) < MEM_SIZE))
        ok = mem == NULL ? -1 : 0;
    Py_XDECREF(mem);
    return ok;
}

/* The writer's part: the masked write of data (n bytes) into 0x0910, then
 * Esc._ew_dc_system_time -> DcUnit.system_time_written at the frame's time t_ns.
 * 1: the corrections moved the clock by more than MOVE_NS (SYNC deadlines are stale);
 * 0: not; -1: error. */
static int write_system_time(PyObject *esc, const uint8_t *data, long n, long long t_ns)
{
    PyObject *memo = get_attr(esc, s_mem);
    PyObject *dc = memo == NULL ? NULL : get_attr(esc, s_dc);
    if (dc == NULL) {
        Py_XDECREF(memo);
        return -1;
    }
    uint8_t *m = (uint8_t *)PyByteArray_AS_STRING(memo);
    int rc = -1, err = 0;
    /* Esc._reg_write: every bit writable here; the hook sees wr_s and wr_e */
    memcpy(m + DC_SYSTEM_TIME, data, (size_t)n);
    if (set_long(esc, s_wr_s, DC_SYSTEM_TIME) < 0 || set_long(esc, s_wr_e, DC_SYSTEM_TIME + n) < 0)
        goto done;
    /* Esc._ew_dc_system_time: the value is the whole register after the write, compared
     * in 8 bytes only if all 8 were written */
    uint64_t value = rd(m, DC_SYSTEM_TIME, 8);
    int nbytes = n >= DC_SYSTEM_TIME_LEN ? 8 : 4;
    /* DcUnit.system_time_written */
    long position = get_long(dc, s_position, &err);
    long long hop = get_long(dc, s_hop_ns, &err);
    long long t_ref = 0;
    i128 local_ref = 0, moved = 0;
    PyObject *tro = err ? NULL : get_attr(dc, s_t_ref);
    PyObject *lro = tro == NULL ? NULL : get_attr(dc, s_local_ref);
    PyObject *mvo = lro == NULL ? NULL : get_attr(dc, s_moved_ns);
    PyObject *spdo = mvo == NULL ? NULL : get_attr(dc, s_spd);
    PyObject *rateo = spdo == NULL ? NULL : get_attr(dc, s_rate_ppb);
    PyObject *drifto = rateo == NULL ? NULL : get_attr(dc, s_drift_ppm);
    double spd = 0, rate = 0, drift = 0;
    if (drifto != NULL) {
        t_ref = PyLong_AsLongLong(tro);
        spd = PyFloat_AsDouble(spdo);
        rate = PyFloat_AsDouble(rateo);
        drift = PyFloat_AsDouble(drifto);
        if (!PyErr_Occurred() && as_i128(lro, &local_ref) == 0)
            as_i128(mvo, &moved);
    }
    Py_XDECREF(tro);
    Py_XDECREF(lro);
    Py_XDECREF(mvo);
    Py_XDECREF(spdo);
    Py_XDECREF(rateo);
    Py_XDECREF(drifto);
    if (err || drifto == NULL || PyErr_Occurred())
        goto done;
    long long t = t_ns + (long long)position * hop; /* arrival_ns */
    uint32_t delay = (uint32_t)rd(m, DC_SYSTEM_TIME_DELAY, 4);
    uint64_t offset = rd(m, DC_SYSTEM_TIME_OFFSET, 8);
    /* local_time(t): (local_ref + int((t - t_ref) * spd)) & MASK64 */
    uint64_t local_now = (uint64_t)(local_ref + (i128)(long long)((double)(t - t_ref) * spd));
    uint64_t local = local_now + offset - delay; /* only local mod 2^64 matters below */
    i128 diff = nbytes < 8 ? (i128)(int32_t)(uint32_t)(local - value)
                           : (i128)(int64_t)(local - value);
    unsigned start = (unsigned)rd(m, DC_SPEED_COUNTER_START, 2) & 0x7FFF;
    double q = (double)start / 1024.0;
    double gain = 1.0 / (q > 2.0 ? q : 2.0); /* max(2.0, q): 2.0 unless q is larger */
    i128 adiff = diff < 0 ? -diff : diff;
    i128 step;
    int rate_set = 0;
    if (adiff > FAR_NS) {
        step = diff; /* far off: jump, as after a new offset */
    } else {
        step = (i128)(long long)((double)(long long)diff * gain);
        double r = rate - (double)(long long)diff * gain * 5.0;
        r = r < 1e6 ? r : 1e6;   /* min(1e6, r) */
        r = r > -1e6 ? r : -1e6; /* max(-1e6, r) */
        rate = r;
        spd = 1.0 + drift * 1e-6 + rate * 1e-9; /* DcUnit._set_rate */
        rate_set = 1;
    }
    i128 new_ref = (i128)local_now - step;
    uint64_t mag = adiff < 0x7FFFFFFF ? (uint64_t)adiff : 0x7FFFFFFF;
    wr(m, DC_SYSTEM_TIME_DIFF, mag | (diff < 0 ? 0x80000000u : 0), 4);
    wr(m, DC_SYSTEM_TIME, (uint64_t)new_ref + offset, 8); /* the corrected local copy */
    moved += step < 0 ? -step : step;
    int jumped = moved > MOVE_NS;
    if (jumped)
        moved = 0;
    if (set_obj(dc, s_local_ref, from_i128(new_ref)) < 0 ||
        set_obj(dc, s_t_ref, PyLong_FromLongLong(t)) < 0 ||
        set_obj(dc, s_moved_ns, from_i128(moved)) < 0)
        goto done;
    if (rate_set && (set_obj(dc, s_rate_ppb, PyFloat_FromDouble(rate)) < 0 ||
                     set_obj(dc, s_spd, PyFloat_FromDouble(spd)) < 0))
        goto done;
    rc = jumped;
done:
    Py_DECREF(memo);
    Py_DECREF(dc);
    return rc;
}

static PyObject *time_loops(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "time_loops(seg, hook)");
        return NULL;
    }
    PyObject *seg = args[0], *hook = args[1];
    int err = 0;
    long n = get_long(seg, s_dc_pending, &err);
    long reader = get_long(seg, s_dc_reader, &err);
    long reach = get_long(seg, s_dc_reach, &err);
    if (err)
        return NULL;
    if (n != 4 && n != 8)
        Py_RETURN_FALSE;
    PyObject *escs = get_attr(seg, s_escs);
    PyObject *before = escs == NULL ? NULL : get_attr(seg, s_dc_before);
    PyObject *after = before == NULL ? NULL : get_attr(seg, s_dc_after);
    PyObject *ctx = after == NULL ? NULL : get_attr(seg, s_ctx);
    PyObject *out = NULL;
    if (ctx == NULL)
        goto done;
    if (!PyList_Check(escs) || reach < 0 || reach > PyList_GET_SIZE(escs) ||
        !PyByteArray_Check(before) || !PyByteArray_Check(after) ||
        PyByteArray_GET_SIZE(before) < n || PyByteArray_GET_SIZE(after) < n) {
        out = Py_NewRef(Py_False);
        goto done;
    }
    /* every writer first: a decline changes nothing */
    for (long i = 0; i < reach; i++) {
        if (i == reader)
            continue;
        int ok = plain_system_time(PyList_GET_ITEM(escs, i), hook, n);
        if (ok <= 0) {
            out = ok < 0 ? NULL : Py_NewRef(Py_False);
            goto done;
        }
    }
    long long t_ns = get_long(ctx, s_t_ns, &err);
    if (err)
        goto done;
    /* Segment.after_reply */
    if (set_long(seg, s_dc_pending, 0) < 0)
        goto done;
    const uint8_t *b = (const uint8_t *)PyByteArray_AS_STRING(before);
    const uint8_t *a = (const uint8_t *)PyByteArray_AS_STRING(after);
    for (long i = 0; i < reach; i++) {
        if (i == reader)
            continue;
        int jumped = write_system_time(PyList_GET_ITEM(escs, i), i < reader ? b : a, n, t_ns);
        if (jumped < 0)
            goto done;
        if (jumped && set_attr(ctx, s_timers_dirty, Py_True) < 0) /* the SYNC deadlines moved */
            goto done;
    }
    out = Py_NewRef(Py_True);
done:
    Py_XDECREF(escs);
    Py_XDECREF(before);
    Py_XDECREF(after);
    Py_XDECREF(ctx);
    return out;
}

static PyMethodDef methods[] = {
    {"time_loops", (PyCFunction)(void (*)(void))time_loops, METH_FASTCALL,
     "time_loops(seg, hook) -> bool: the pending FRMW's writers served (True), or nothing "
     "changed (False)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_dcloop", "Compiled DC time loops of an FRMW of 0x0910.", -1,
    methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__dcloop(void)
{
    static const Name names[] = {
        {&s_escs, "escs"}, {&s_ctx, "ctx"}, {&s_t_ns, "t_ns"},
        {&s_timers_dirty, "timers_dirty"}, {&s_dc_pending, "_dc_pending"},
        {&s_dc_reader, "_dc_reader"}, {&s_dc_reach, "_dc_reach"},
        {&s_dc_before, "_dc_before"}, {&s_dc_after, "_dc_after"},
        {&s_sm_windows, "sm_windows"}, {&s_t, "t"}, {&s_ecat_wmask, "ecat_wmask"},
        {&s_ecat_w_hooked, "ecat_w_hooked"}, {&s_ecat_w, "ecat_w"}, {&s_mem, "mem"},
        {&s_dc, "dc"}, {&s_wr_s, "wr_s"}, {&s_wr_e, "wr_e"}, {&s_position, "position"},
        {&s_hop_ns, "hop_ns"}, {&s_local_ref, "local_ref"}, {&s_t_ref, "t_ref"},
        {&s_spd, "spd"}, {&s_rate_ppb, "rate_ppb"}, {&s_drift_ppm, "drift_ppm"},
        {&s_moved_ns, "moved_ns"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return NULL;
    two64 = PyLong_FromString("18446744073709551616", NULL, 10); /* 2^64 */
    if (two64 == NULL)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddIntConstant(m, "MOVE_NS", MOVE_NS) < 0 ||
        PyModule_AddIntConstant(m, "FAR_NS", FAR_NS) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME", DC_SYSTEM_TIME) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_OFFSET", DC_SYSTEM_TIME_OFFSET) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_DELAY", DC_SYSTEM_TIME_DELAY) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_DIFF", DC_SYSTEM_TIME_DIFF) < 0 ||
        PyModule_AddIntConstant(m, "DC_SPEED_COUNTER_START", DC_SPEED_COUNTER_START) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
