/* Esc.sm_windows for the compiled paths (_serve.c, _dcloop.c): whether a physical access
 * to [start, end) is a plain memory or register access, or goes to a SyncManager
 * (Esc.ecat_read / Esc.ecat_write look the windows up first). Ref: TMC8460 §5.49. */
#ifndef ECATSIM_WINDOWS_H
#define ECATSIM_WINDOWS_H
#include <Python.h>

#include "../_attr.h"

/* 1: no SM window of ``esc`` (attribute ``name``, a tuple of (start, end, sm)) overlaps
 * [start, end); 0: one does, or the windows are not that shape (the caller leaves the
 * access to Python); -1: error. */
static inline int no_sm_window(PyObject *esc, PyObject *name, long start, long end)
{
    PyObject *wins = get_attr(esc, name);
    if (wins == NULL)
        return -1;
    int ok = PyTuple_Check(wins) ? 1 : 0;
    for (Py_ssize_t i = 0; ok == 1 && i < PyTuple_GET_SIZE(wins); i++) {
        PyObject *w = PyTuple_GET_ITEM(wins, i);
        if (!PyTuple_Check(w) || PyTuple_GET_SIZE(w) < 2) {
            ok = 0;
            break;
        }
        long ws = PyLong_AsLong(PyTuple_GET_ITEM(w, 0));
        long we = PyLong_AsLong(PyTuple_GET_ITEM(w, 1));
        if (PyErr_Occurred())
            ok = -1;
        else if (ws < end && start < we)
            ok = 0;
    }
    Py_DECREF(wins);
    return ok;
}

#endif
