/* Compiled logical datagram (LRD, LWR, LRW) across the ESCs of a segment, shared by
 * ecatsim/esc/_logical.c (Segment._walk) and ecatsim/_serve.c (the responder): the work
 * of Esc.ecat_logical for every ESC in the walk, when every FMMU the datagram meets is
 * byte-aligned and routed to one buffered SyncManager (FmmuMap.sm), as process data
 * mapped by every master is. Otherwise nothing is changed and the Python walk runs.
 *
 * logical_run(escs, cmd, lad, data, dlen) -> WKC increment; LOGICAL_DECLINED: not
 *   handled, nothing changed; LOGICAL_ERROR: a Python exception is set.
 *   escs: Segment.logical (ESCs with active FMMUs, in the frame's order).
 *
 * Per ESC the writes come first (the data as received), then the reads overlay it; WKC
 * +1 for a read, +1 (LWR) or +2 (LRW) for a write. The SM accesses are the ECAT face of
 * SyncManager (writer_write / reader_read / peek, with the 3-buffer exchange, status and
 * event bits) and the watchdog trigger of Esc.wd_pd_trigger (Watchdog.trigger). The
 * Python methods are the reference: tests/unit/slave/test_cycle_compiled.py and
 * tests/golden run both.
 *
 * Ref: ETG.1000.4 §5.4.3 Table 12 (WKC); TMC8460 §5.48 (FMMU), §5.49 Tables 88-89 (SM);
 * docs/decisions.md P6.
 */
#ifndef ECATSIM_LOGICAL_H
#define ECATSIM_LOGICAL_H
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "_sm.h"

#define LOGICAL_DECLINED (-1)
#define LOGICAL_ERROR (-2)
#define LRD 0x0A
#define LWR 0x0B
#define LRW 0x0C
#define SM_CTRL_WATCHDOG 0x40
#define WD_STATUS_PD 0x0440
#define MAX_MAPS 1024

static PyObject *s_fmmus, *s_lbit, *s_lend, *s_lstart, *s_lstop, *s_pstart, *s_read,
    *s_write, *s_aligned, *s_sm, *s_mem, *s_ctx, *s_pending, *s_position, *s_wd, *s_timeout_ns, *s_deadline_ns, *s_t_ns;

/* One FMMU the datagram meets, resolved in the first pass. */
typedef struct {
    Py_ssize_t esc;  /* index in escs */
    PyObject *sm;    /* borrowed: FmmuMap.sm (kept alive by the FmmuMap) */
    long lstart, lstop, pstart;
    int read, write;
} Map;

/* The event side of one ESC (Esc struct of _sm.h): new references in *e. */
static int esc_open(Esc *e, PyObject *esc, PyObject **mem)
{
    *mem = get_attr(esc, s_mem);
    if (*mem == NULL)
        return -1;
    if (!PyByteArray_Check(*mem) || PyByteArray_GET_SIZE(*mem) < MEM_SIZE) {
        PyErr_SetString(PyExc_TypeError, "Esc.mem must be a 64 KiB bytearray");
        return -1;
    }
    e->m = (uint8_t *)PyByteArray_AS_STRING(*mem);
    e->esc = esc;
    e->ctx = get_attr(esc, s_ctx);
    if (e->ctx == NULL)
        return -1;
    e->pending = get_attr(e->ctx, s_pending);
    if (e->pending == NULL)
        return -1;
    e->position = get_attr(esc, s_position);
    return e->position == NULL ? -1 : 0;
}

static void esc_close(Esc *e, PyObject *mem)
{
    Py_XDECREF(mem);
    Py_XDECREF(e->ctx);
    Py_XDECREF(e->pending);
    Py_XDECREF(e->position);
}

/* Esc.wd_pd_trigger: Watchdog.trigger at the frame's time (ctx.t_ns): the process-data
 * watchdog restarts if it is enabled, and 0x0440 bit 0 reads "active". Ref: TMC8460
 * §5.41 Table 55, §5.42 Table 56. */
static int wd_pd_trigger(Esc *e)
{
    PyObject *wd = get_attr(e->esc, s_wd);
    if (wd == NULL)
        return -1;
    int err = 0;
    long long timeout = get_long(wd, s_timeout_ns, &err);
    long long t = timeout && !err ? get_long(e->ctx, s_t_ns, &err) : 0;
    if (!err && timeout && set_long(wd, s_deadline_ns, t + timeout) < 0)
        err = 1;
    Py_DECREF(wd);
    if (err)
        return -1;
    e->m[WD_STATUS_PD] |= 0x01;
    return 0;
}

/* SyncManager.ecat_write (writer_write + _writer_access, buffered) after ecat_may_write;
 * 1 written, 0 refused. */
static int sm_ecat_write(Esc *e, PyObject *smobj, long off, const uint8_t *data, long n)
{
    Sm sm;
    if (sm_load(&sm, smobj) < 0)
        return -1;
    if (!(sm.ecat_side_writes && sm.active && !sm.locked))
        return 0;
    int first = off == 0, last = off + n >= sm.length;
    long base = sm.start + sm.w * sm.length;
    if (base + off + n > MEM_SIZE)
        return 0; /* cannot happen for a routed FMMU; never write outside memory */
    memcpy(e->m + base + off, data, (size_t)n);
    if (first) {
        sm.w_open = 1;
        sm.status &= ~SM_ST_IRQ_READ;
    }
    if (last) {
        sm.w_open = 0;
        long latest = sm.l = sm.w;
        if (sm.r_open && sm.r != latest)
            sm.w = 3 - latest - sm.r;
        else
            sm.w = latest == 0 ? 1 : 0;
        sm.status |= SM_ST_IRQ_WRITE;
    }
    if ((first || last) && sm_sync(e, &sm) < 0)
        return -1;
    if (sm_store(&sm) < 0)
        return -1;
    int err = 0;
    long control = get_long(smobj, s_control, &err);
    if (err)
        return -1;
    if (control & SM_CTRL_WATCHDOG)
        return wd_pd_trigger(e) < 0 ? -1 : 1;
    return 1;
}

/* SyncManager.ecat_read after ecat_may_read: peek (ECAT writes this SM) or reader_read
 * (_reader_open, _reader_access); 1 read, 0 refused. */
static int sm_ecat_read(Esc *e, PyObject *smobj, long off, uint8_t *out, long n)
{
    Sm sm;
    if (sm_load(&sm, smobj) < 0)
        return -1;
    if (!(sm.active && !sm.locked))
        return 0;
    if (sm.ecat_side_writes) {
        long b = sm.r_open ? sm.r : (sm.l >= 0 ? sm.l : sm.r);
        long base = sm.start + b * sm.length;
        if (base + off + n > MEM_SIZE)
            return 0;
        memcpy(out, e->m + base + off, (size_t)n);
        return 1;
    }
    int first = off == 0, last = off + n >= sm.length;
    if (first) {
        if (sm.l >= 0)
            sm.r = sm.l;
        else if (sm.r == sm.w)
            sm.r = (sm.w + 1) % 3;
        sm.r_open = 1;
    }
    long b = sm.r_open ? sm.r : (sm.l >= 0 ? sm.l : sm.r);
    long base = sm.start + b * sm.length;
    if (base + off + n > MEM_SIZE)
        return 0;
    memcpy(out, e->m + base + off, (size_t)n);
    if (first)
        sm.status &= ~SM_ST_IRQ_WRITE;
    if (last) {
        sm.r_open = 0;
        sm.status |= SM_ST_IRQ_READ;
    }
    if ((first || last) && sm_sync(e, &sm) < 0)
        return -1;
    return sm_store(&sm) < 0 ? -1 : 1;
}

static long logical_run(PyObject *escs, long cmd, long long lad, uint8_t *data,
                        Py_ssize_t dlen)
{
    if (cmd != LRD && cmd != LWR && cmd != LRW)
        return LOGICAL_DECLINED;
    long long lo_bit = lad * 8, hi_bit = (lad + dlen) * 8;

    /* ---- pass 1: every FMMU the datagram meets, resolved; none eligible -> Python */
    static Map maps[MAX_MAPS];
    int nmaps = 0;
    Py_ssize_t n_escs = PyList_GET_SIZE(escs);
    for (Py_ssize_t k = 0; k < n_escs; k++) {
        PyObject *fmmus = get_attr(PyList_GET_ITEM(escs, k), s_fmmus);
        if (fmmus == NULL)
            return LOGICAL_ERROR;
        if (!PyTuple_Check(fmmus)) {
            Py_DECREF(fmmus);
            return LOGICAL_DECLINED;
        }
        for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(fmmus); i++) {
            PyObject *f = PyTuple_GET_ITEM(fmmus, i);
            int err = 0;
            long lbit = get_long(f, s_lbit, &err), lend = get_long(f, s_lend, &err);
            int rd = get_bool(f, s_read, &err), wr = get_bool(f, s_write, &err);
            if (err) {
                Py_DECREF(fmmus);
                return LOGICAL_ERROR;
            }
            if (!(lbit < hi_bit && lo_bit < lend))
                continue;
            int takes_part = (wr && cmd != LRD) || (rd && cmd != LWR);
            if (!takes_part)
                continue;
            Map *mp = &maps[nmaps];
            int aligned = get_bool(f, s_aligned, &err);
            if (nmaps >= MAX_MAPS || err) {
                Py_DECREF(fmmus);
                if (PyErr_Occurred())
                    return LOGICAL_ERROR;
                return LOGICAL_DECLINED;
            }
            PyObject *sm = get_attr(f, s_sm);
            if (sm == NULL) {
                Py_DECREF(fmmus);
                return LOGICAL_ERROR;
            }
            int ok = aligned && sm != Py_None && !get_bool(sm, s_mailbox, &err) && !err;
            Py_DECREF(sm); /* the FmmuMap keeps it */
            if (ok) {
                mp->lstart = get_long(f, s_lstart, &err);
                mp->lstop = get_long(f, s_lstop, &err);
                mp->pstart = get_long(f, s_pstart, &err);
            }
            if (!ok || err) {
                Py_DECREF(fmmus);
                if (PyErr_Occurred())
                    return LOGICAL_ERROR;
                return LOGICAL_DECLINED; /* a bit-wise map, or one not in one SM window */
            }
            mp->esc = k;
            mp->sm = sm;
            mp->read = rd;
            mp->write = wr;
            nmaps++;
        }
        Py_DECREF(fmmus);
    }

    /* ---- pass 2: per ESC, the writes, then the reads (Esc.ecat_logical, _fmmu_xfer) */
    long inc = 0;
    int m = 0;
    while (m < nmaps) {
        Py_ssize_t k = maps[m].esc;
        int end = m;
        while (end < nmaps && maps[end].esc == k)
            end++;
        Esc e = {0};
        PyObject *mem = NULL;
        if (esc_open(&e, PyList_GET_ITEM(escs, k), &mem) < 0) {
            esc_close(&e, mem);
            return LOGICAL_ERROR;
        }
        int wr_ok = 0, rd_ok = 0;
        for (int pass = 0; pass < 2; pass++) {
            int writing = pass == 0;
            if (writing ? cmd == LRD : cmd == LWR)
                continue;
            for (int j = m; j < end; j++) {
                Map *mp = &maps[j];
                if (writing ? !mp->write : !mp->read)
                    continue;
                long long lo = lad > mp->lstart ? lad : mp->lstart;
                long long hi = lad + dlen < mp->lstop ? lad + dlen : mp->lstop;
                if (hi <= lo)
                    continue;
                long phys = mp->pstart + (long)(lo - mp->lstart);
                int err = 0;
                long start = get_long(mp->sm, s_start, &err);
                if (err) {
                    esc_close(&e, mem);
                    return LOGICAL_ERROR;
                }
                int rc = writing ? sm_ecat_write(&e, mp->sm, phys - start, data + (lo - lad),
                                                 (long)(hi - lo))
                                 : sm_ecat_read(&e, mp->sm, phys - start, data + (lo - lad),
                                                (long)(hi - lo));
                if (rc < 0) {
                    esc_close(&e, mem);
                    return LOGICAL_ERROR;
                }
                if (rc) {
                    if (writing)
                        wr_ok = 1;
                    else
                        rd_ok = 1;
                }
            }
        }
        esc_close(&e, mem);
        if (cmd == LRW)
            inc += (rd_ok ? 1 : 0) + (wr_ok ? 2 : 0);
        else
            inc += (rd_ok || wr_ok) ? 1 : 0;
        m = end;
    }
    return inc;
}

/* Intern the names logical_run uses (module init); -1 on failure. */
static int logical_init(void)
{
    static const Name names[] = {
        {&s_fmmus, "fmmus"}, {&s_lbit, "lbit"}, {&s_lend, "lend"}, {&s_lstart, "lstart"},
        {&s_lstop, "lstop"}, {&s_pstart, "pstart"}, {&s_read, "read"}, {&s_write, "write"},
        {&s_aligned, "aligned"}, {&s_sm, "sm"}, {&s_mem, "mem"}, {&s_ctx, "ctx"},
        {&s_pending, "pending"}, {&s_position, "position"},
        {&s_wd, "wd"}, {&s_timeout_ns, "timeout_ns"}, {&s_deadline_ns, "deadline_ns"},
        {&s_t_ns, "t_ns"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return -1;
    return sm_names_init();
}

#endif
