/* Attribute access shared by the compiled paths (_logical.c, _cycle.c, _drive.c,
 * _serve.c): the state they work on lives in the Python objects, read and written by name.
 * Errors are flagged in *err (get_*) or returned as -1 (set_*, intern_names).
 *
 * The hot objects (SyncManager, FmmuMap, DcUnit, Watchdog, FrameContext) use __slots__.
 * For those, get_attr/set_attr read and write the member's slot directly, at the offset
 * its member descriptor gives, found once per (type, name) and kept in a small cache that
 * the type's version tag invalidates (it changes whenever the class is modified). This is
 * what PyObject_GenericGetAttr/SetAttr do for such a member, without the type lookup and
 * the descriptor call on every access: fewer cache lines touched by a frame that arrives
 * after a sleep. Any other attribute takes the generic path. */
#ifndef ECATSIM_ATTR_H
#define ECATSIM_ATTR_H
#include <Python.h>
#include <stdint.h>
#include <structmember.h>

#define SLOT_CACHE 512

/* One resolved (type, name): offset of the slot, or -1 (not a plain writable member). */
typedef struct {
    PyTypeObject *type;
    PyObject *name;
    unsigned int version;
    Py_ssize_t offset;
} SlotEntry;

static SlotEntry slot_cache[SLOT_CACHE];

/* The slot offset of member ``name`` in instances of ``tp``, or -1: use the generic path. */
static Py_ssize_t slot_offset(PyTypeObject *tp, PyObject *name)
{
    unsigned int version = tp->tp_version_tag;
    SlotEntry *e =
        &slot_cache[((((uintptr_t)tp >> 4) * 31u) ^ ((uintptr_t)name >> 4)) % SLOT_CACHE];
    if (e->type == tp && e->name == name && e->version == version && version != 0 &&
        (tp->tp_flags & Py_TPFLAGS_VALID_VERSION_TAG))
        return e->offset;
    Py_ssize_t off = -1;
    if (tp->tp_getattro == PyObject_GenericGetAttr && tp->tp_setattro == PyObject_GenericSetAttr) {
        PyObject *d = PyObject_GetAttr((PyObject *)tp, name); /* the class's descriptor */
        if (d == NULL) {
            PyErr_Clear();
        } else {
            if (Py_IS_TYPE(d, &PyMemberDescr_Type)) {
                PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
                if (m->type == T_OBJECT_EX && !(m->flags & READONLY))
                    off = m->offset;
            }
            Py_DECREF(d);
        }
    }
    version = tp->tp_version_tag; /* the lookup above assigns one if there was none */
    if (version != 0 && (tp->tp_flags & Py_TPFLAGS_VALID_VERSION_TAG)) {
        e->type = tp;
        e->name = name;
        e->version = version;
        e->offset = off;
    }
    return off;
}

/* getattr(o, name): a new reference, or NULL with the exception set. */
static inline PyObject *get_attr(PyObject *o, PyObject *name)
{
    Py_ssize_t off = slot_offset(Py_TYPE(o), name);
    if (off >= 0) {
        PyObject *v = *(PyObject **)((char *)o + off);
        if (v != NULL) {
            Py_INCREF(v);
            return v;
        }
    }
    return PyObject_GetAttr(o, name); /* also raises for an unset slot */
}

/* setattr(o, name, v): 0, or -1 with the exception set. */
static inline int set_attr(PyObject *o, PyObject *name, PyObject *v)
{
    Py_ssize_t off = slot_offset(Py_TYPE(o), name);
    if (off >= 0) {
        PyObject **p = (PyObject **)((char *)o + off);
        PyObject *old = *p;
        Py_INCREF(v);
        *p = v;
        Py_XDECREF(old);
        return 0;
    }
    return PyObject_SetAttr(o, name, v);
}

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
    PyObject *v = get_attr(o, name);
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
    PyObject *v = get_attr(o, name);
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
    int rc = set_attr(o, name, v);
    Py_DECREF(v);
    return rc;
}

#endif
