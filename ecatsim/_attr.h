/* Attribute access shared by the compiled paths (_logical.c, _cycle.c, _drive.c): the
 * state they work on lives in the Python objects, read and written by name.
 * Errors are flagged in *err (get_*) or returned as -1 (set_*, intern_names). */
#ifndef ECATSIM_ATTR_H
#define ECATSIM_ATTR_H
#include <Python.h>

/* One attribute name to intern at module init. */
typedef struct {
    PyObject **slot;
    const char *name;
} Name;

static inline int intern_names(const Name *names, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        *names[i].slot = PyUnicode_InternFromString(names[i].name);
        if (*names[i].slot == NULL)
            return -1;
    }
    return 0;
}

/* An int attribute; on failure 0, with *err set and the exception pending. */
static inline long get_long(PyObject *o, PyObject *name, int *err)
{
    PyObject *v = PyObject_GetAttr(o, name);
    if (v == NULL) {
        *err = 1;
        return 0;
    }
    long x = PyLong_AsLong(v);
    Py_DECREF(v);
    if (x == -1 && PyErr_Occurred())
        *err = 1;
    return x;
}

static inline int get_bool(PyObject *o, PyObject *name, int *err)
{
    PyObject *v = PyObject_GetAttr(o, name);
    if (v == NULL) {
        *err = 1;
        return 0;
    }
    int x = PyObject_IsTrue(v);
    Py_DECREF(v);
    if (x < 0)
        *err = 1;
    return x;
}

static inline int set_long(PyObject *o, PyObject *name, long long x)
{
    PyObject *v = PyLong_FromLongLong(x);
    if (v == NULL)
        return -1;
    int rc = PyObject_SetAttr(o, name, v);
    Py_DECREF(v);
    return rc;
}

#endif
