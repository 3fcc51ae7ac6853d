/* SyncManager state and the event registers, shared by the compiled paths
 * (ecatsim/esc/_logical.c: the ECAT side; ecatsim/slave/_cycle.c: the PDI side).
 * Each function transcribes the Python method it names; the Python classes
 * (ecatsim/esc/sm.py SyncManager, ecatsim/esc/core.py Esc) are the reference.
 * An SM's state lives in its Python object: sm_load() reads it, sm_store() and
 * sm_sync() write it back. Ref: TMC8460 §5.29-5.33 (events), §5.49 Tables 85-91.
 */
#ifndef ECATSIM_SM_H
#define ECATSIM_SM_H
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "../_attr.h"
#include "_events.h"

/* Register addresses and bits (ecatsim/esc/regs.py; the test checks they agree). */
#define DL_STATUS 0x0110
#define ECAT_EVENT_MASK 0x0200
#define ECAT_EVENT_REQUEST 0x0210
#define DC_PULSE_LENGTH 0x0982
#define EV_AL_CONTROL 0x0001
#define EV_SM_ACTIVATION 0x0010
#define EV_WATCHDOG_PD 0x0040
#define EV_SM0 0x0100
#define ECAT_EV_SM0 0x0010
#define SM_ST_IRQ_WRITE 0x01
#define SM_ST_IRQ_READ 0x02
#define SM_ST_BUF_SHIFT 4
#define SM_ST_READ_OPEN 0x40
#define SM_ST_WRITE_OPEN 0x80
#define MEM_SIZE 0x10000

static PyObject *s_active, *s_locked, *s_mailbox, *s_ecat_side_writes, *s_start, *s_length,
    *s_w, *s_l, *s_r, *s_r_open, *s_w_open, *s_status, *s_mirror, *s_irq_to_ecat,
    *s_irq_to_pdi, *s_status_addr, *s_n, *s_ecat_irq, *s_irq_dirty, *s_control, *s_mbx_full;

/* The names sm_load reads, in its order (filled by sm_names_init). */
static PyObject *sm_names[17];

/* Intern the attribute names above (module init); -1 on failure. */
static int sm_names_init(void)
{
    static const Name names[] = {
        {&s_active, "active"}, {&s_locked, "locked"}, {&s_mailbox, "mailbox"},
        {&s_ecat_side_writes, "ecat_side_writes"}, {&s_start, "start"},
        {&s_length, "length"}, {&s_w, "w"}, {&s_l, "l"}, {&s_r, "r"}, {&s_r_open, "r_open"},
        {&s_w_open, "w_open"}, {&s_status, "status"}, {&s_mirror, "mirror"},
        {&s_irq_to_ecat, "irq_to_ecat"}, {&s_irq_to_pdi, "irq_to_pdi"},
        {&s_status_addr, "status_addr"}, {&s_n, "n"}, {&s_ecat_irq, "ecat_irq"},
        {&s_irq_dirty, "irq_dirty"}, {&s_control, "control"}, {&s_mbx_full, "mbx_full"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return -1;
    PyObject *order[17] = {s_active, s_locked, s_mailbox, s_ecat_side_writes, s_r_open,
                           s_w_open, s_start, s_length, s_w, s_l, s_r, s_status, s_mirror,
                           s_irq_to_ecat, s_irq_to_pdi, s_status_addr, s_n};
    memcpy(sm_names, order, sizeof order);
    return 0;
}

/* A SyncManager's state, read once per call and written back where it changed. */
typedef struct {
    PyObject *obj;
    int active, locked, mailbox, ecat_side_writes, r_open, w_open;
    long start, length, w, l, r, status, mirror, irq_to_ecat, irq_to_pdi, status_addr, n;
} Sm;

/* The members sm_load reads, in the order of SM_* below. */
enum {
    SM_ACTIVE, SM_LOCKED, SM_MAILBOX, SM_ECAT_SIDE_WRITES, SM_R_OPEN, SM_W_OPEN, SM_START,
    SM_LENGTH, SM_W, SM_L, SM_R, SM_STATUS, SM_MIRROR, SM_IRQ_TO_ECAT, SM_IRQ_TO_PDI,
    SM_STATUS_ADDR, SM_N, SM_FIELDS
};

static Layout sm_layout;

/* Member i: through the layout if it holds for obj (``lay``) and the value is an exact
 * int or bool, by name otherwise (Python's conversion and errors). */
static inline long sm_long(PyObject *obj, int lay, int i, int *err)
{
    PyObject *v = lay ? LAYOUT_SLOT(obj, &sm_layout, i) : NULL;
    if (v != NULL && PyLong_CheckExact(v)) {
        int overflow;
        long x = PyLong_AsLongAndOverflow(v, &overflow);
        if (!overflow)
            return x;
    }
    return get_long(obj, sm_names[i], err);
}

static inline int sm_bool(PyObject *obj, int lay, int i, int *err)
{
    PyObject *v = lay ? LAYOUT_SLOT(obj, &sm_layout, i) : NULL;
    if (v == Py_True || v == Py_False)
        return v == Py_True;
    return get_bool(obj, sm_names[i], err);
}

static int sm_load(Sm *sm, PyObject *obj)
{
    int err = 0, lay = layout_of(&sm_layout, obj, sm_names, SM_FIELDS);
    sm->obj = obj;
    sm->active = sm_bool(obj, lay, SM_ACTIVE, &err);
    sm->locked = sm_bool(obj, lay, SM_LOCKED, &err);
    sm->mailbox = sm_bool(obj, lay, SM_MAILBOX, &err);
    sm->ecat_side_writes = sm_bool(obj, lay, SM_ECAT_SIDE_WRITES, &err);
    sm->r_open = sm_bool(obj, lay, SM_R_OPEN, &err);
    sm->w_open = sm_bool(obj, lay, SM_W_OPEN, &err);
    sm->start = sm_long(obj, lay, SM_START, &err);
    sm->length = sm_long(obj, lay, SM_LENGTH, &err);
    sm->w = sm_long(obj, lay, SM_W, &err);
    sm->l = sm_long(obj, lay, SM_L, &err);
    sm->r = sm_long(obj, lay, SM_R, &err);
    sm->status = sm_long(obj, lay, SM_STATUS, &err);
    sm->mirror = sm_long(obj, lay, SM_MIRROR, &err);
    sm->irq_to_ecat = sm_long(obj, lay, SM_IRQ_TO_ECAT, &err);
    sm->irq_to_pdi = sm_long(obj, lay, SM_IRQ_TO_PDI, &err);
    sm->status_addr = sm_long(obj, lay, SM_STATUS_ADDR, &err);
    sm->n = sm_long(obj, lay, SM_N, &err);
    return err ? -1 : 0;
}

/* Esc._irq_update: ECAT event request AND ECAT event mask, into the IRQ field. */
static int irq_update(Esc *e)
{
    long irq = (long)(rd16(e->m, ECAT_EVENT_REQUEST) & rd16(e->m, ECAT_EVENT_MASK));
    int err = 0;
    long cur = get_long(e->esc, s_ecat_irq, &err);
    if (err)
        return -1;
    if (irq != cur) {
        if (set_long(e->esc, s_ecat_irq, irq) < 0)
            return -1;
        if (set_attr(e->ctx, s_irq_dirty, Py_True) < 0)
            return -1;
    }
    return 0;
}

/* Esc._set_ecat_event / _clr_ecat_event */
static int ecat_event(Esc *e, unsigned bits, int set)
{
    unsigned v = rd16(e->m, ECAT_EVENT_REQUEST);
    unsigned nv = set ? (v | bits) : (v & ~bits);
    if (nv == v)
        return 0;
    wr16(e->m, ECAT_EVENT_REQUEST, nv);
    return irq_update(e);
}

/* SyncManager._sync (buffered mode) and Esc.sm_status_changed. */
static int sm_sync(Esc *e, Sm *sm)
{
    long st = sm->status & (SM_ST_IRQ_WRITE | SM_ST_IRQ_READ);
    st |= (sm->l >= 0 ? sm->l : 3) << SM_ST_BUF_SHIFT;
    if (sm->r_open)
        st |= SM_ST_READ_OPEN;
    if (sm->w_open)
        st |= SM_ST_WRITE_OPEN;
    sm->status = st;
    e->m[sm->status_addr] = (uint8_t)st;
    long mirror = ((st & sm->irq_to_ecat) ? 1 : 0) | ((st & sm->irq_to_pdi) ? 2 : 0);
    if (mirror != sm->mirror) {
        sm->mirror = mirror;
        if (set_long(sm->obj, s_mirror, mirror) < 0)
            return -1;
        if (ecat_event(e, ECAT_EV_SM0 << sm->n, (int)(mirror & 1)) < 0)
            return -1;
        uint32_t abit = (uint32_t)EV_SM0 << sm->n;
        if ((mirror & 2) ? set_al_event(e, abit) : clr_al_event(e, abit))
            return -1;
    }
    return 0;
}

/* setattr through the layout when it holds for obj, by name otherwise. */
static int sm_set(PyObject *obj, int i, PyObject *v)
{
    if (v == NULL)
        return -1;
    if (!layout_holds(&sm_layout, obj)) {
        int rc = set_attr(obj, sm_names[i], v);
        Py_DECREF(v);
        return rc;
    }
    PyObject **p = &LAYOUT_SLOT(obj, &sm_layout, i);
    PyObject *old = *p;
    *p = v; /* the reference is handed over */
    Py_XDECREF(old);
    return 0;
}

static int sm_store(Sm *sm)
{
    PyObject *o = sm->obj;
    if (sm_set(o, SM_W, PyLong_FromLong(sm->w)) < 0 ||
        sm_set(o, SM_L, PyLong_FromLong(sm->l)) < 0 ||
        sm_set(o, SM_R, PyLong_FromLong(sm->r)) < 0 ||
        sm_set(o, SM_STATUS, PyLong_FromLong(sm->status)) < 0)
        return -1;
    if (sm_set(o, SM_R_OPEN, Py_NewRef(sm->r_open ? Py_True : Py_False)) < 0)
        return -1;
    return sm_set(o, SM_W_OPEN, Py_NewRef(sm->w_open ? Py_True : Py_False));
}

#endif
