/* Compiled DC loops (optional): the time loops of an FRMW of 0x0910 (decision P11) and the
 * SYNC0 pulses of a segment (decision P12).
 *
 * The time loops are the work Segment.after_reply leaves for the writers of the frame's
 * system time, each a physical write of 0x0910 (Esc.ecat_write -> _reg_write ->
 * Esc._ew_dc_system_time -> DcUnit.system_time_written), for every writer in one call.
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
 * pulses(seg, t, esc_type, dc_type) -> bool
 *   Segment.sync_until(t): every SYNC0 pulse due by host time t, ESC by ESC in wire order,
 *   each handled at its own time (Esc.sync0_tick -> DcUnit.sync0_pulse, the AL event,
 *   then the firmware's service(d) if its PDI interrupt is raised), and the segment's
 *   next SYNC deadline.
 *   True:  done here.
 *   False: a precondition does not hold (the timers are dirty, an ESC or DC unit of
 *          another type, a SYNC unit with SYNC1 enabled or scheduled, a firmware list
 *          that does not cover an ESC); nothing was changed and the caller runs the
 *          Python loop, the reference.
 *
 * The arithmetic is Python's: the DC unit's local clock is piecewise linear in double
 * precision (DcUnit.local_time), its reference kept as an unbounded Python int (here a
 * 128-bit integer), the clock speed and rate as doubles computed in the same order (the
 * module is built with -ffp-contract=off). tests/unit/slave/test_cycle_compiled.py runs
 * both and compares every register, the DC units' state and the timers flag.
 *
 * Ref: TMC8460 §5.50.2 Tables 95-101 (system time, offset, delay, difference, speed
 * counter), §5.50.4 Tables 105-112 (SYNC0 generation), §5.32 (AL event 0x0220.2);
 * ETG.1000.4 §5.4.3 Table 12 (FRMW); ETG.1000.6 §5.3; docs/decisions.md P7, P11, P12.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "../_attr.h"
#include "../_module.h"
#include "_events.h"
#include "_windows.h"

/* ecatsim/esc/regs.py, ecatsim/esc/dc.py (the test checks they agree) */
#define DC_SYSTEM_TIME 0x0910
#define DC_SYSTEM_TIME_LEN 8
#define DC_SYSTEM_TIME_OFFSET 0x0920
#define DC_SYSTEM_TIME_DELAY 0x0928
#define DC_SYSTEM_TIME_DIFF 0x092C
#define DC_SPEED_COUNTER_START 0x0930
#define DC_SPEED_COUNTER_DIFF 0x0932
#define MOVE_NS 50000
#define FAR_NS 1000000
#define MEM_SIZE 0x10000
#define SYNC_LATCH_CONFIG 0x0151
#define DC_START_TIME 0x0990
#define DC_SYNC0_CYCLE 0x09A0
/* ecatsim/segment.py */
#define MAX_SYNC0_CATCHUP 64
#define PULSE_HINT_MARGIN_NS 200000
#define NO_DEADLINE ((i128)1 << 62)

typedef __int128 i128;

static PyObject *s_escs, *s_ctx, *s_t_ns, *s_timers_dirty, *s_dc_pending, *s_dc_reader,
    *s_dc_reach, *s_dc_before, *s_dc_after, *s_sm_windows, *s_t, *s_ecat_wmask,
    *s_ecat_w_hooked, *s_ecat_w, *s_mem, *s_dc, *s_wr_s, *s_wr_e, *s_position, *s_hop_ns,
    *s_local_ref, *s_t_ref, *s_spd, *s_rate_ppb, *s_drift_ppm, *s_moved_ns, *s_sync_escs,
    *s_firmware, *s_pending, *s_next_sync0, *s_next_sync1, *s_service, *s_sync0_ticks,
    *s_sync0_late_ns, *s_next_sync, *s_pulse_hint, *s_pdi_ns, *two64;

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

/* A DC unit's clock as DcUnit reads it: local_ref at host time t_ref, spd ticks per ns. */
typedef struct {
    i128 local_ref;
    long long t_ref;
    double spd;
} DcClock;

static int clock_load(PyObject *dc, DcClock *c)
{
    PyObject *lro = get_attr(dc, s_local_ref);
    PyObject *tro = lro == NULL ? NULL : get_attr(dc, s_t_ref);
    PyObject *spdo = tro == NULL ? NULL : get_attr(dc, s_spd);
    int rc = -1;
    if (spdo != NULL && as_i128(lro, &c->local_ref) == 0) {
        c->t_ref = PyLong_AsLongLong(tro);
        c->spd = PyFloat_AsDouble(spdo);
        rc = PyErr_Occurred() ? -1 : 0;
    }
    Py_XDECREF(lro);
    Py_XDECREF(tro);
    Py_XDECREF(spdo);
    return rc;
}

/* Python's float(i) for an integer of up to 126 bits: correctly rounded. */
static inline double to_double(i128 v)
{
    if (v >= INT64_MIN && v <= INT64_MAX)
        return (double)(long long)v;
    return (double)v;
}

/* DcUnit.local_time(now) = (local_ref + int((now - t_ref) * spd)) & MASK64 */
static inline uint64_t local_time(const DcClock *c, i128 now)
{
    return (uint64_t)(c->local_ref + (i128)(to_double(now - c->t_ref) * c->spd));
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
    DcClock c;
    if (err || clock_load(dc, &c) < 0)
        goto done;
    i128 moved = 0;
    PyObject *mvo = get_attr(dc, s_moved_ns);
    PyObject *rateo = mvo == NULL ? NULL : get_attr(dc, s_rate_ppb);
    PyObject *drifto = rateo == NULL ? NULL : get_attr(dc, s_drift_ppm);
    double spd = c.spd, rate = 0, drift = 0;
    if (drifto != NULL) {
        rate = PyFloat_AsDouble(rateo);
        drift = PyFloat_AsDouble(drifto);
        if (!PyErr_Occurred())
            as_i128(mvo, &moved);
    }
    Py_XDECREF(mvo);
    Py_XDECREF(rateo);
    Py_XDECREF(drifto);
    if (drifto == NULL || PyErr_Occurred())
        goto done;
    long long t = t_ns + (long long)position * hop; /* arrival_ns */
    uint32_t delay = (uint32_t)rd(m, DC_SYSTEM_TIME_DELAY, 4);
    uint64_t offset = rd(m, DC_SYSTEM_TIME_OFFSET, 8);
    uint64_t local_now = local_time(&c, t);
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
    /* DcUnit._speed_counter_diff: the rate correction (new or kept) as 0x0932 */
    long long lim = (long long)start - 0x7F;
    lim = lim > 0 ? lim : 0;
    long long scd = (long long)(rate * 5e-9 * (double)(start + 2) * (double)(start + 2));
    scd = scd < lim ? scd : lim;
    scd = scd > -lim ? scd : -lim;
    wr(m, DC_SPEED_COUNTER_DIFF, (uint64_t)scd & 0xFFFF, 2);
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


/* DcUnit.host_time_of: when the host clock reaches ``system`` here. */
static i128 host_time_of(const DcClock *c, const uint8_t *m, i128 system)
{
    uint64_t offset = rd(m, DC_SYSTEM_TIME_OFFSET, 8);
    int64_t local = (int64_t)((uint64_t)system - offset - (uint64_t)c->local_ref);
    return (i128)c->t_ref + (i128)((double)local / c->spd);
}

/* DcUnit.system_time(now) = (local_time(now) + offset) & MASK64. */
static uint64_t system_time(const DcClock *c, const uint8_t *m, i128 now)
{
    return local_time(c, now) + rd(m, DC_SYSTEM_TIME_OFFSET, 8);
}

/* dc.next_sync0: 1 with *out set, 0 for None, -1 on error. */
static int next_sync0(PyObject *dc, i128 *out)
{
    PyObject *v = get_attr(dc, s_next_sync0);
    if (v == NULL)
        return -1;
    int rc = v == Py_None ? 0 : (as_i128(v, out) == 0 ? 1 : -1);
    Py_DECREF(v);
    return rc;
}

/* Esc.sync0_tick(now) -> DcUnit.sync0_pulse(now) (SYNC1 off), then AL event 0x0220.2 if
 * SYNC0 is mapped to it, and the timers flag once a single shot is done. */
static int sync0_tick(Esc *e, PyObject *dc, i128 now)
{
    uint8_t *m = e->m;
    i128 nxt;
    int has = next_sync0(dc, &nxt);
    if (has <= 0)
        return has;
    uint32_t cycle = (uint32_t)rd(m, DC_SYNC0_CYCLE, 4);
    int pulse = 0;
    PyObject *nv;
    if (!(m[DC_ACTIVATION] & 0x02)) {
        nv = cycle ? from_i128(nxt + cycle) : Py_NewRef(Py_None); /* SYNC1 only */
    } else {
        m[DC_ACTIVATION_STATUS] &= 0xFE;
        m[DC_SYNC0_STATUS] |= 0x01;
        if (cycle == 0) {
            nv = Py_NewRef(Py_None); /* single shot */
        } else {
            DcClock c;
            if (clock_load(dc, &c) < 0)
                return -1;
            nxt += cycle;
            i128 behind = (i128)system_time(&c, m, now) - nxt;
            if (behind >= cycle)
                nxt += (behind / cycle) * cycle;
            wr(m, DC_START_TIME, (uint64_t)nxt, 8);
            nv = from_i128(nxt);
        }
        pulse = (m[SYNC_LATCH_CONFIG] & 0x08) != 0;
    }
    int none = nv == Py_None;
    if (set_obj(dc, s_next_sync0, nv) < 0)
        return -1;
    if (pulse && set_al_event(e, EV_SYNC0) < 0)
        return -1;
    if (none && set_attr(e->ctx, s_timers_dirty, Py_True) < 0)
        return -1;
    return 0;
}

/* The ESC's view for the event functions (borrowed references, alive for the call). */
static int esc_load(PyObject *esc, Esc *e, PyObject **hold)
{
    PyObject *mem = get_attr(esc, s_mem);
    PyObject *ctx = mem == NULL ? NULL : get_attr(esc, s_ctx);
    PyObject *pending = ctx == NULL ? NULL : get_attr(ctx, s_pending);
    PyObject *position = pending == NULL ? NULL : get_attr(esc, s_position);
    hold[0] = mem;
    hold[1] = ctx;
    hold[2] = pending;
    hold[3] = position;
    if (position == NULL)
        return -1;
    if (!PyByteArray_Check(mem) || PyByteArray_GET_SIZE(mem) < MEM_SIZE || !PySet_Check(pending)) {
        PyErr_SetString(PyExc_TypeError, "pulses: an ESC's memory or pending set");
        return -1;
    }
    e->m = (uint8_t *)PyByteArray_AS_STRING(mem);
    e->esc = esc;
    e->ctx = ctx;
    e->pending = pending;
    e->position = position;
    return 0;
}

/* Preconditions of one ESC (nothing is changed): 1 it applies, 0 not, -1 error. */
static int pulse_applies(PyObject *esc, PyObject *esc_type, PyObject *dc_type,
                         PyObject *firmware)
{
    if ((PyObject *)Py_TYPE(esc) != esc_type)
        return 0;
    PyObject *dc = get_attr(esc, s_dc);
    PyObject *mem = dc == NULL ? NULL : get_attr(esc, s_mem);
    PyObject *n1 = mem == NULL ? NULL : get_attr(dc, s_next_sync1);
    int err = 0, ok = -1;
    long position = n1 == NULL ? 0 : get_long(esc, s_position, &err);
    if (n1 != NULL && !err) {
        ok = (PyObject *)Py_TYPE(dc) == dc_type && n1 == Py_None && PyByteArray_Check(mem) &&
             PyByteArray_GET_SIZE(mem) >= MEM_SIZE &&
             !(((uint8_t *)PyByteArray_AS_STRING(mem))[DC_ACTIVATION] & 0x04) &&
             (PyList_GET_SIZE(firmware) == 0 ||
              (position >= 0 && position < PyList_GET_SIZE(firmware)));
    }
    Py_XDECREF(dc);
    Py_XDECREF(mem);
    Py_XDECREF(n1);
    return ok;
}

/* One ESC of Segment.sync_until: its due pulses, then its next deadline into *nxt. */
static int pulse_esc(PyObject *esc, PyObject *firmware, PyObject *seg_ctx, i128 t, i128 *nxt,
                     long long *ticks, i128 *late)
{
    PyObject *hold[4] = {NULL, NULL, NULL, NULL};
    PyObject *dc = get_attr(esc, s_dc);
    Esc e;
    int rc = -1;
    if (dc == NULL || esc_load(esc, &e, hold) < 0)
        goto done;
    PyObject *fw = NULL; /* borrowed from the list */
    if (PyList_GET_SIZE(firmware) > 0) {
        long position = PyLong_AsLong(e.position);
        if (position < 0 || position >= PyList_GET_SIZE(firmware)) {
            if (!PyErr_Occurred())
                PyErr_SetString(PyExc_IndexError, "pulses: no firmware for an ESC");
            goto done;
        }
        fw = PyList_GET_ITEM(firmware, position);
    }
    i128 d = 0;
    int has = 0;
    int k;
    for (k = 0; k <= MAX_SYNC0_CATCHUP; k++) {
        PyObject *n1 = get_attr(dc, s_next_sync1);
        if (n1 == NULL)
            goto done;
        Py_DECREF(n1);
        if (n1 != Py_None) { /* SYNC1 appeared: cannot happen with 0x0981 bit 2 clear */
            PyErr_SetString(PyExc_RuntimeError, "pulses: a SYNC1 pulse was scheduled");
            goto done;
        }
        DcClock c;
        has = next_sync0(dc, &d);
        if (has < 0 || (has && clock_load(dc, &c) < 0))
            goto done;
        if (has)
            d = host_time_of(&c, e.m, d);
        if (!has || d > t)
            break;
        if (k == MAX_SYNC0_CATCHUP)
            d = t; /* too far behind: fire once now, the missed pulses are skipped */
        if (sync0_tick(&e, dc, d) < 0)
            goto done;
        *ticks += 1;
        if (t - d > *late)
            *late = t - d;
        if (fw != NULL) {
            PyObject *pending = get_attr(seg_ctx, s_pending);
            int in = pending == NULL ? -1 : PySet_Contains(pending, e.position);
            Py_XDECREF(pending);
            if (in < 0)
                goto done;
            if (in) {
                PyObject *dobj = from_i128(d);
                /* Segment.sync_until: ctx.pdi_ns = d, the PDI work's time */
                if (dobj != NULL && set_attr(seg_ctx, s_pdi_ns, dobj) < 0) {
                    Py_DECREF(dobj);
                    goto done;
                }
                PyObject *r = dobj == NULL ? NULL : PyObject_CallMethodOneArg(fw, s_service, dobj);
                Py_XDECREF(dobj);
                if (r == NULL)
                    goto done;
                Py_DECREF(r);
            }
        }
    }
    if (k > MAX_SYNC0_CATCHUP) { /* the for loop's else: the deadline after the last pulse */
        DcClock c;
        has = next_sync0(dc, &d);
        if (has < 0 || (has && clock_load(dc, &c) < 0))
            goto done;
        if (has)
            d = host_time_of(&c, e.m, d);
    }
    if (has && d < *nxt)
        *nxt = d;
    rc = 0;
done:
    Py_XDECREF(dc);
    for (int i = 0; i < 4; i++)
        Py_XDECREF(hold[i]);
    return rc;
}

static PyObject *pulses(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "pulses(seg, t, esc_type, dc_type)");
        return NULL;
    }
    PyObject *seg = args[0];
    i128 t;
    if (as_i128(args[1], &t) < 0)
        return NULL;
    PyObject *ctx = get_attr(seg, s_ctx);
    PyObject *escs = ctx == NULL ? NULL : get_attr(seg, s_sync_escs);
    PyObject *firmware = escs == NULL ? NULL : get_attr(seg, s_firmware);
    PyObject *out = NULL;
    int err = 0;
    if (firmware == NULL)
        goto done;
    int dirty = get_bool(ctx, s_timers_dirty, &err);
    if (err)
        goto done;
    if (dirty || !PyList_Check(escs) || !PyList_Check(firmware)) {
        out = Py_NewRef(Py_False); /* Segment.sync_escs recomputes the list first */
        goto done;
    }
    /* every ESC first: a decline changes nothing */
    Py_ssize_t n = PyList_GET_SIZE(escs);
    for (Py_ssize_t i = 0; i < n; i++) {
        int ok = pulse_applies(PyList_GET_ITEM(escs, i), args[2], args[3], firmware);
        if (ok <= 0) {
            out = ok < 0 ? NULL : Py_NewRef(Py_False);
            goto done;
        }
    }
    i128 nxt = NO_DEADLINE, late = 0;
    long long ticks = 0;
    PyObject *lo = get_attr(seg, s_sync0_late_ns);
    int lrc = lo == NULL ? -1 : as_i128(lo, &late);
    Py_XDECREF(lo);
    if (lrc < 0)
        goto done;
    i128 late0 = late;
    /* the list as it was at the start, as Python's for loop over the property */
    PyObject *list = PyList_GetSlice(escs, 0, n);
    if (list == NULL)
        goto done;
    int rc = 0;
    for (Py_ssize_t i = 0; rc == 0 && i < n; i++)
        rc = pulse_esc(PyList_GET_ITEM(list, i), firmware, ctx, t, &nxt, &ticks, &late);
    Py_DECREF(list);
    if (ticks) {
        long long before = get_long(seg, s_sync0_ticks, &err);
        if (err || set_long(seg, s_sync0_ticks, before + ticks) < 0)
            goto done;
    }
    if (late != late0 && set_obj(seg, s_sync0_late_ns, from_i128(late)) < 0)
        goto done;
    if (rc < 0)
        goto done;
    /* Segment._set_next_sync */
    if (set_obj(seg, s_next_sync, from_i128(nxt)) < 0 ||
        set_obj(seg, s_pulse_hint, from_i128(nxt - PULSE_HINT_MARGIN_NS)) < 0)
        goto done;
    out = Py_NewRef(Py_True);
done:
    Py_XDECREF(ctx);
    Py_XDECREF(escs);
    Py_XDECREF(firmware);
    return out;
}

static PyMethodDef methods[] = {
    {"time_loops", (PyCFunction)(void (*)(void))time_loops, METH_FASTCALL,
     "time_loops(seg, hook) -> bool: the pending FRMW's writers served (True), or nothing "
     "changed (False)."},
    {"pulses", (PyCFunction)(void (*)(void))pulses, METH_FASTCALL,
     "pulses(seg, t, esc_type, dc_type) -> bool: Segment.sync_until(t) done (True), or "
     "nothing changed (False)."},
    {NULL, NULL, 0, NULL},
};

static int exec_module(PyObject *m)
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
        {&s_moved_ns, "moved_ns"}, {&s_sync_escs, "_sync_escs"}, {&s_firmware, "firmware"},
        {&s_pending, "pending"}, {&s_next_sync0, "next_sync0"}, {&s_next_sync1, "next_sync1"},
        {&s_service, "service"}, {&s_sync0_ticks, "sync0_ticks"},
        {&s_sync0_late_ns, "sync0_late_ns"}, {&s_next_sync, "_next_sync"},
        {&s_pulse_hint, "_pulse_hint"}, {&s_pdi_ns, "pdi_ns"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return -1;
    Py_XSETREF(two64, PyLong_FromString("18446744073709551616", NULL, 10)); /* 2^64 */
    if (two64 == NULL)
        return -1;
    if (PyModule_AddIntConstant(m, "MOVE_NS", MOVE_NS) < 0 ||
        PyModule_AddIntConstant(m, "FAR_NS", FAR_NS) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME", DC_SYSTEM_TIME) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_OFFSET", DC_SYSTEM_TIME_OFFSET) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_DELAY", DC_SYSTEM_TIME_DELAY) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYSTEM_TIME_DIFF", DC_SYSTEM_TIME_DIFF) < 0 ||
        PyModule_AddIntConstant(m, "DC_SPEED_COUNTER_START", DC_SPEED_COUNTER_START) < 0 ||
        PyModule_AddIntConstant(m, "DC_SPEED_COUNTER_DIFF", DC_SPEED_COUNTER_DIFF) < 0 ||
        PyModule_AddIntConstant(m, "SYNC_LATCH_CONFIG", SYNC_LATCH_CONFIG) < 0 ||
        PyModule_AddIntConstant(m, "DC_START_TIME", DC_START_TIME) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYNC0_CYCLE", DC_SYNC0_CYCLE) < 0 ||
        PyModule_AddIntConstant(m, "DC_ACTIVATION", DC_ACTIVATION) < 0 ||
        PyModule_AddIntConstant(m, "DC_ACTIVATION_STATUS", DC_ACTIVATION_STATUS) < 0 ||
        PyModule_AddIntConstant(m, "DC_SYNC0_STATUS", DC_SYNC0_STATUS) < 0 ||
        PyModule_AddIntConstant(m, "AL_EVENT_REQUEST", AL_EVENT_REQUEST) < 0 ||
        PyModule_AddIntConstant(m, "AL_EVENT_MASK", AL_EVENT_MASK) < 0 ||
        PyModule_AddIntConstant(m, "EV_SYNC0", EV_SYNC0) < 0 ||
        PyModule_AddIntConstant(m, "MAX_SYNC0_CATCHUP", MAX_SYNC0_CATCHUP) < 0 ||
        PyModule_AddIntConstant(m, "PULSE_HINT_MARGIN_NS", PULSE_HINT_MARGIN_NS) < 0 ||
        PyModule_AddIntConstant(m, "NO_DEADLINE", (long)NO_DEADLINE) < 0)
        return -1;
    return 0;
}

static PyModuleDef_Slot slots[] = ECATSIM_MODULE_SLOTS(exec_module);

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_dcloop",
    "Compiled DC loops: the time loops of an FRMW of 0x0910, the SYNC0 pulses.", 0, methods,
    slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__dcloop(void) { return PyModuleDef_Init(&module); }
