/* Compiled logical datagram (LRD, LWR, LRW) across the ESCs of a segment (optional): the
 * work of Esc.ecat_logical for every ESC in the walk, when every FMMU the datagram meets
 * is byte-aligned and routed to one buffered SyncManager (FmmuMap.sm), as process data
 * mapped by every master is. Otherwise nothing is changed and the Python walk runs.
 *
 * run(escs, cmd, lad, buf, d0, dlen) -> int (the work is in _logical.h)
 *   escs: Segment.logical (ESCs with active FMMUs, in the frame's order);
 *   buf:  the frame (bytearray); the datagram's data is buf[d0 : d0 + dlen].
 *   Returns the WKC increment, or -1: not handled, nothing changed.
 *
 * Per ESC the writes come first (the data as received), then the reads overlay it; WKC
 * +1 for a read, +1 (LWR) or +2 (LRW) for a write. The SM accesses are the ECAT face of
 * SyncManager (writer_write / reader_read / peek, with the 3-buffer exchange, status and
 * event bits) and the watchdog trigger of Esc.wd_pd_trigger. The Python methods are the
 * reference: tests/unit/slave/test_cycle_compiled.py and tests/golden run both.
 *
 * Ref: ETG.1000.4 §5.4.3 Table 12 (WKC); TMC8460 §5.48 (FMMU), §5.49 Tables 88-89 (SM);
 * docs/decisions.md P6.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "../_module.h"
#include "_logical.h"

static PyObject *run(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 6 || !PyList_Check(args[0]) || !PyByteArray_Check(args[3])) {
        PyErr_SetString(PyExc_TypeError, "run(escs: list, cmd, lad, buf: bytearray, d0, dlen)");
        return NULL;
    }
    long cmd = PyLong_AsLong(args[1]);
    long long lad = PyLong_AsLongLong(args[2]);
    Py_ssize_t d0 = PyLong_AsSsize_t(args[4]), dlen = PyLong_AsSsize_t(args[5]);
    if (PyErr_Occurred())
        return NULL;
    if (d0 < 0 || dlen < 0 || d0 + dlen > PyByteArray_GET_SIZE(args[3])) {
        PyErr_SetString(PyExc_ValueError, "datagram outside the frame");
        return NULL;
    }
    uint8_t *data = (uint8_t *)PyByteArray_AS_STRING(args[3]) + d0;
    long inc = logical_run(args[0], cmd, lad, data, dlen);
    return inc == LOGICAL_ERROR ? NULL : PyLong_FromLong(inc);
}

static PyMethodDef methods[] = {
    {"run", (PyCFunction)(void (*)(void))run, METH_FASTCALL,
     "run(escs, cmd, lad, buf, d0, dlen) -> WKC increment, or -1 (not handled)."},
    {NULL, NULL, 0, NULL},
};

static int exec_module(PyObject *m)
{
    (void)m;
    return logical_init();
}

static PyModuleDef_Slot slots[] = ECATSIM_MODULE_SLOTS(exec_module);

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_logical", "Compiled logical datagrams (FMMU to SM).", 0,
    methods, slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__logical(void) { return PyModuleDef_Init(&module); }
