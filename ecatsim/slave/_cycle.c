/* Compiled DC cycle of one CoE slave's firmware: the PDI-side work of Firmware.service for
 * a SYNC0 event in DC synchronous mode, when nothing else is pending.
 *
 * run(cyc, now_ns) -> bool
 *   cyc: the tuple ecatsim.slave.cycle.build() makes (stable references only; everything
 *        else is read live, every call).
 *   True:  the SYNC0 event was served here, exactly as Firmware.service would have served
 *          it (SYNC0 acknowledged, SM2 read and the outputs applied in OP, the inputs
 *          packed and written to SM3, the SM status and event registers updated).
 *   False: a precondition does not hold; nothing was changed and the caller runs the
 *          Python firmware (the reference model).
 *
 * The device itself (CiA 402 drive, servo) stays in Python: this code calls its
 * outputs_applied() and update_inputs(), so its logic has one implementation.
 * Every step below names the Python function it transcribes; tests/unit/slave/
 * test_cycle_compiled.py runs both and compares memory, OD values and SM state.
 *
 * Ref: TMC8460 §5.32 (AL event), §5.49 Tables 88-89 (SM status, 3-buffer exchange),
 * §5.50.4 Tables 106-109 (SYNC0 status); ETG.1000.6 §5.3 (DC synchronous mode);
 * docs/decisions.md P3.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#include "../_module.h"
#include "../esc/_pdi.h"

/* Events the Python firmware serves other than SYNC0 and process data: any of them sends
 * the call to Python. SM0 is a mailbox request. SM1 (the master took a reply) is not
 * here: with no reply queued, MailboxEngine.flush() has nothing to do, and the event
 * stays raised until the next reply is written. */
#define OTHER_EVENTS (EV_AL_CONTROL | EV_SM_ACTIVATION | EV_WATCHDOG_PD | EV_SM0)
#define SM_PD_OUT_EVENT (EV_SM0 << 2)

/* cyc tuple layout (ecatsim/slave/cycle.py, build()) */
enum {
    C_FW, C_ESC, C_MEM, C_CTX, C_PENDING, C_POSITION, C_SM2, C_SM3, C_RX_ENTRIES,
    C_RX_LAYOUT, C_TX_ENTRIES, C_TX_LAYOUT, C_RX_SIZE, C_TX_SIZE, C_DEVICE, C_DEVICE_STEP,
    C_MBX, C_APP,
    C_OP, C_SAFEOP, C_MASK_DC, C_LEN
};

static PyObject *s_state, *s_event_mask, *s_pd_masked, *s_out, *s_value, *s_outputs_applied,
    *s_update_inputs, *s_pack_inputs, *s_service_mailbox;

/* A process image layout: 3 bytes per mapped entry, offset (LE 16) and a struct code. */
static int code_size(char c)
{
    switch (c) {
    case 'b': case 'B': return 1;
    case 'h': case 'H': return 2;
    case 'i': case 'I': return 4;
    case 'q': case 'Q': return 8;
    default: return 0;
    }
}

/* PdoImage.set_outputs (the one-struct codec): each entry's value from the image. */
static int unpack_rx(const uint8_t *buf, PyObject *entries, PyObject *layout)
{
    const uint8_t *lay = (const uint8_t *)PyBytes_AS_STRING(layout);
    Py_ssize_t n = PyTuple_GET_SIZE(entries);
    for (Py_ssize_t i = 0; i < n; i++) {
        const uint8_t *p = buf + (lay[3 * i] | (lay[3 * i + 1] << 8));
        char c = (char)lay[3 * i + 2];
        uint64_t u = 0;
        int sz = code_size(c);
        for (int k = sz - 1; k >= 0; k--)
            u = (u << 8) | p[k];
        PyObject *v;
        switch (c) {
        case 'b': v = PyLong_FromLong((int8_t)u); break;
        case 'h': v = PyLong_FromLong((int16_t)u); break;
        case 'i': v = PyLong_FromLong((int32_t)u); break;
        case 'q': v = PyLong_FromLongLong((int64_t)u); break;
        default: v = PyLong_FromUnsignedLongLong(u); break;
        }
        if (v == NULL)
            return -1;
        int rc = set_attr(PyTuple_GET_ITEM(entries, i), s_value, v);
        Py_DECREF(v);
        if (rc < 0)
            return -1;
    }
    return 0;
}

/* PdoImage.get_inputs' struct.pack: 1 packed, 0 a value is not an int of its type's range
 * (the caller then lets Python encode it entry by entry), -1 error. */
static int pack_tx(uint8_t *buf, PyObject *entries, PyObject *layout)
{
    const uint8_t *lay = (const uint8_t *)PyBytes_AS_STRING(layout);
    Py_ssize_t n = PyTuple_GET_SIZE(entries);
    for (Py_ssize_t i = 0; i < n; i++) {
        char c = (char)lay[3 * i + 2];
        PyObject *v = get_attr(PyTuple_GET_ITEM(entries, i), s_value);
        if (v == NULL)
            return -1;
        if (!PyLong_Check(v)) {
            Py_DECREF(v);
            return 0;
        }
        int over = 0;
        long long x = PyLong_AsLongLongAndOverflow(v, &over);
        uint64_t u;
        int ok;
        if (c == 'Q') {
            u = PyLong_AsUnsignedLongLong(v);
            ok = !(u == (uint64_t)-1 && PyErr_Occurred());
            PyErr_Clear();
        } else {
            u = (uint64_t)x;
            switch (c) {
            case 'b': ok = x >= -128 && x <= 127; break;
            case 'B': ok = x >= 0 && x <= 0xFF; break;
            case 'h': ok = x >= -32768 && x <= 32767; break;
            case 'H': ok = x >= 0 && x <= 0xFFFF; break;
            case 'i': ok = x >= INT32_MIN && x <= INT32_MAX; break;
            case 'I': ok = x >= 0 && x <= 0xFFFFFFFFLL; break;
            default: ok = 1; break; /* 'q' */
            }
            ok = ok && !over;
        }
        Py_DECREF(v);
        if (!ok)
            return 0;
        uint8_t *p = buf + (lay[3 * i] | (lay[3 * i + 1] << 8));
        for (int k = 0, sz = code_size(c); k < sz; k++, u >>= 8)
            p[k] = (uint8_t)u;
    }
    return 1;
}

static PyObject *run(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2 || !PyTuple_Check(args[0]) || PyTuple_GET_SIZE(args[0]) != C_LEN) {
        PyErr_SetString(PyExc_TypeError, "run(cyc, now_ns): cyc from ecatsim.slave.cycle");
        return NULL;
    }
    PyObject *cyc = args[0], *now = args[1];
#define ITEM(k) PyTuple_GET_ITEM(cyc, k)
    PyObject *fw = ITEM(C_FW);
    PyObject *memobj = ITEM(C_MEM);
    if (!PyByteArray_Check(memobj) || PyByteArray_GET_SIZE(memobj) < MEM_SIZE) {
        PyErr_SetString(PyExc_TypeError, "cyc: ESC memory must be a 64 KiB bytearray");
        return NULL;
    }
    Esc e = {(uint8_t *)PyByteArray_AS_STRING(memobj), ITEM(C_ESC), ITEM(C_CTX),
             ITEM(C_PENDING), ITEM(C_POSITION)};

    /* ---- preconditions (Firmware.service's branches); nothing changes before these. */
    if (!pdi_operational(&e))
        Py_RETURN_FALSE;
    uint32_t ev = pdi_al_event(&e);
    if (!(ev & EV_SYNC0) || (ev & OTHER_EVENTS))
        Py_RETURN_FALSE;
    if (!pdi_sync0_running(&e))
        Py_RETURN_FALSE; /* not DC synchronous with the pulses running */
    PyObject *state = get_attr(fw, s_state);
    if (state == NULL)
        return NULL;
    int op = state == ITEM(C_OP);
    int safeop = state == ITEM(C_SAFEOP);
    Py_DECREF(state);
    if (!op && !safeop)
        Py_RETURN_FALSE;
    int err = 0;
    long mask = get_long(fw, s_event_mask, &err);
    int masked = get_bool(fw, s_pd_masked, &err);
    if (err)
        return NULL;
    if (!masked || mask != PyLong_AsLong(ITEM(C_MASK_DC)))
        Py_RETURN_FALSE; /* service_mailbox would rewrite the event mask */
    PyObject *mbx = ITEM(C_MBX);
    if (mbx != Py_None) {
        int queued = get_bool(mbx, s_out, &err);
        if (err)
            return NULL;
        if (queued)
            Py_RETURN_FALSE;
    }
    Sm sm2, sm3;
    if (pdi_sm_load(&sm2, ITEM(C_SM2)) < 0 || pdi_sm_load(&sm3, ITEM(C_SM3)) < 0)
        return NULL;
    int read_out = (ev & SM_PD_OUT_EVENT) != 0;
    long rx_size = PyLong_AsLong(ITEM(C_RX_SIZE)), tx_size = PyLong_AsLong(ITEM(C_TX_SIZE));
    if (read_out && !(pdi_sm_may(&e, &sm2, 1) && sm2.length >= rx_size))
        Py_RETURN_FALSE;
    if (!pdi_sm_may(&e, &sm3, 0))
        Py_RETURN_FALSE;

    /* ---- p.u8(DC_SYNC0_STATUS) */
    if (pdi_ack_sync0(&e) < 0)
        return NULL;

    /* ---- SM2 read; in OP the outputs are written into the OD (app.set_outputs) */
    int applied = 0;
    if (read_out) {
        const uint8_t *out = pdi_sm_read(&e, &sm2);
        if (out == NULL)
            return NULL;
        if (op) {
            if (unpack_rx(out, ITEM(C_RX_ENTRIES), ITEM(C_RX_LAYOUT)) < 0)
                return NULL;
            applied = 1;
        }
    }

    /* ---- the device: outputs_applied (if applied), then update_inputs (app.get_inputs);
     * through its compiled steady cycle where it has one and it applies */
    int done = 0;
    PyObject *ds = ITEM(C_DEVICE_STEP);
    if (ds != Py_None) {
        PyObject *fargs[3] = {PyTuple_GET_ITEM(ds, 1), now, applied ? Py_True : Py_False};
        PyObject *r = PyObject_Vectorcall(PyTuple_GET_ITEM(ds, 0), fargs, 3, NULL);
        if (r == NULL)
            return NULL;
        done = r == Py_True;
        Py_DECREF(r);
    }
    if (!done) {
        if (applied) {
            PyObject *r = PyObject_CallMethodOneArg(ITEM(C_DEVICE), s_outputs_applied, now);
            if (r == NULL)
                return NULL;
            Py_DECREF(r);
        }
        PyObject *r = PyObject_CallMethodOneArg(ITEM(C_DEVICE), s_update_inputs, now);
        if (r == NULL)
            return NULL;
        Py_DECREF(r);
    }

    /* ---- Firmware._write_inputs: Pdi.sm_write(SM3) */
    /* SM3 was checked writable above (Pdi.sm_write would otherwise refuse); the device
     * does not touch the SMs, so the state loaded then is still the state now. */
    uint8_t *buf = pdi_sm_write_buffer(&e, &sm3);
    long n = sm3.length;
    int packed = tx_size <= n ? pack_tx(buf, ITEM(C_TX_ENTRIES), ITEM(C_TX_LAYOUT)) : 0;
    if (packed < 0)
        return NULL;
    if (packed) {
        /* struct padding bytes are zero, and so is the rest of the window */
        const uint8_t *lay = (const uint8_t *)PyBytes_AS_STRING(ITEM(C_TX_LAYOUT));
        Py_ssize_t ne = PyTuple_GET_SIZE(ITEM(C_TX_ENTRIES));
        long pos = 0;
        for (Py_ssize_t i = 0; i < ne; i++) {
            long off = lay[3 * i] | (lay[3 * i + 1] << 8);
            if (off > pos)
                memset(buf + pos, 0, (size_t)(off - pos));
            pos = off + code_size((char)lay[3 * i + 2]);
        }
        if (n > pos)
            memset(buf + pos, 0, (size_t)(n - pos));
    } else {
        PyObject *data = PyObject_CallMethodNoArgs(ITEM(C_APP), s_pack_inputs);
        if (data == NULL)
            return NULL;
        if (!PyBytes_Check(data)) {
            Py_DECREF(data);
            PyErr_SetString(PyExc_TypeError, "pack_inputs() must return bytes");
            return NULL;
        }
        Py_ssize_t dn = PyBytes_GET_SIZE(data);
        if (dn > n)
            dn = n;
        memcpy(buf, PyBytes_AS_STRING(data), (size_t)dn);
        if (n > dn)
            memset(buf + dn, 0, (size_t)(n - dn));
        Py_DECREF(data);
    }
    if (pdi_sm_written(&e, &sm3) < 0)
        return NULL;

    /* ---- Firmware.service_mailbox: the mask changes only if the device queued a message
     * (an emergency); Python does that part. */
    if (mbx != Py_None) {
        int queued = get_bool(mbx, s_out, &err);
        if (err)
            return NULL;
        if (queued) {
            PyObject *evo = PyLong_FromUnsignedLong(ev);
            if (evo == NULL)
                return NULL;
            PyObject *rr = PyObject_CallMethodObjArgs(fw, s_service_mailbox, evo, now, NULL);
            Py_DECREF(evo);
            if (rr == NULL)
                return NULL;
            Py_DECREF(rr);
        }
    }
#undef ITEM
    Py_RETURN_TRUE;
}

static PyObject *constants(PyObject *self, PyObject *unused)
{
    (void)self;
    (void)unused;
    return Py_BuildValue(
        "{sisisisisisisisisisisisisisisisisisisisisisisi}", "DL_STATUS", DL_STATUS,
        "ECAT_EVENT_MASK", ECAT_EVENT_MASK, "AL_EVENT_MASK", AL_EVENT_MASK,
        "ECAT_EVENT_REQUEST", ECAT_EVENT_REQUEST, "AL_EVENT_REQUEST", AL_EVENT_REQUEST,
        "DC_ACTIVATION", DC_ACTIVATION, "DC_PULSE_LENGTH", DC_PULSE_LENGTH,
        "DC_ACTIVATION_STATUS", DC_ACTIVATION_STATUS, "DC_SYNC0_STATUS", DC_SYNC0_STATUS,
        "EV_AL_CONTROL", EV_AL_CONTROL, "EV_SYNC0", EV_SYNC0, "EV_SM_ACTIVATION",
        EV_SM_ACTIVATION, "EV_WATCHDOG_PD", EV_WATCHDOG_PD, "EV_SM0", EV_SM0, "ECAT_EV_SM0",
        ECAT_EV_SM0, "SM_ST_IRQ_WRITE", SM_ST_IRQ_WRITE, "SM_ST_IRQ_READ", SM_ST_IRQ_READ,
        "SM_ST_BUF_SHIFT", SM_ST_BUF_SHIFT, "SM_ST_READ_OPEN", SM_ST_READ_OPEN,
        "SM_ST_WRITE_OPEN", SM_ST_WRITE_OPEN, "SM_ACT_LATCH_PDI", SM_ACT_LATCH_PDI,
        "MEM_SIZE", MEM_SIZE, "N_ITEMS", C_LEN);
}

static PyMethodDef methods[] = {
    {"run", (PyCFunction)(void (*)(void))run, METH_FASTCALL,
     "run(cyc, now_ns) -> bool: serve a SYNC0 event of one slave, or False to let Python."},
    {"constants", constants, METH_NOARGS, "The register constants compiled in (for tests)."},
    {NULL, NULL, 0, NULL},
};

static int exec_module(PyObject *m)
{
    (void)m;
    static const Name names[] = {
        {&s_state, "state"}, {&s_event_mask, "event_mask"}, {&s_pd_masked, "pd_masked"},
        {&s_out, "out"}, {&s_value, "value"},
        {&s_outputs_applied, "outputs_applied"}, {&s_update_inputs, "update_inputs"},
        {&s_pack_inputs, "pack_inputs"}, {&s_service_mailbox, "service_mailbox"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0)
        return -1;
    return sm_names_init();
}

static PyModuleDef_Slot slots[] = ECATSIM_MODULE_SLOTS(exec_module);

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cycle", "Compiled DC cycle of the slave firmware.", 0, methods,
    slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__cycle(void) { return PyModuleDef_Init(&module); }
