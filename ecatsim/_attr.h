/* Attribute access shared by the compiled paths (_logical.c, _cycle.c, _serve.c,
 * _dcloop.c): the state they work on lives in the Python objects, read and written at
 * their __slots__ offsets where the attribute is a plain slot, by name otherwise
 * (decision P10). Errors are flagged in *err (get_*) or returned as -1 (set_*,
 * intern_names). */
#ifndef ECATSIM_ATTR_H
#define ECATSIM_ATTR_H
#include <Python.h>
#include <stdint.h>
#include <structmember.h>

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

/* Where a __slots__ attribute lives in an object, found once per (name, type) through
 * the type's member descriptor and kept while the type is unchanged (its version tag):
 * the compiled paths read their state after a sleep, when every line is a cache miss,
 * and a slot read touches two lines where PyObject_GetAttr touches about ten. */
typedef struct {
    PyObject *name;
    PyTypeObject *type;
    unsigned int version;
    Py_ssize_t offset;
} SlotCache;

#define SLOT_CACHE_SIZE 256
static SlotCache slot_cache[SLOT_CACHE_SIZE];

/* The slot of ``name`` in ``o``, or NULL: not a plain __slots__ member (Python's lookup
 * then decides, errors included). */
static inline PyObject **slot_of(PyObject *o, PyObject *name)
{
    PyTypeObject *t = Py_TYPE(o);
    SlotCache *c = &slot_cache[((uintptr_t)name >> 4) % SLOT_CACHE_SIZE];
    if (c->name == name && c->type == t && c->version == t->tp_version_tag && c->version)
        return (PyObject **)((char *)o + c->offset);
    PyObject *d = _PyType_Lookup(t, name);
    if (d == NULL || !Py_IS_TYPE(d, &PyMemberDescr_Type) ||
        !PyType_HasFeature(t, Py_TPFLAGS_VALID_VERSION_TAG))
        return NULL;
    PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
    if (m->type != T_OBJECT_EX || (m->flags & READONLY))
        return NULL;
    c->name = name;
    c->type = t;
    c->version = t->tp_version_tag;
    c->offset = m->offset;
    return (PyObject **)((char *)o + m->offset);
}

/* The offsets of several __slots__ members of one type, found together: an object read
 * member by member through slot_of touches one cache entry per member; through a Layout
 * it touches one table. */
#define LAYOUT_MAX 24
typedef struct {
    PyTypeObject *type;
    unsigned int version;
    int n;
    Py_ssize_t offset[LAYOUT_MAX];
} Layout;

/* 1: every one of names[:n] is a plain __slots__ member of o's type, their offsets in L;
 * 0: not (read them by name). */
static inline int layout_of(Layout *L, PyObject *o, PyObject *const *names, int n)
{
    PyTypeObject *t = Py_TYPE(o);
    if (L->type == t && L->version == t->tp_version_tag && L->version && L->n == n)
        return 1;
    L->type = NULL; /* invalid while it is filled */
    if (n > LAYOUT_MAX)
        return 0;
    for (int i = 0; i < n; i++) {
        PyObject *d = _PyType_Lookup(t, names[i]);
        if (d == NULL || !Py_IS_TYPE(d, &PyMemberDescr_Type))
            return 0;
        PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
        if (m->type != T_OBJECT_EX || (m->flags & READONLY))
            return 0;
        L->offset[i] = m->offset;
    }
    if (!PyType_HasFeature(t, Py_TPFLAGS_VALID_VERSION_TAG))
        return 0;
    L->version = t->tp_version_tag;
    L->n = n;
    L->type = t;
    return 1;
}

/* Member i of a Layout (borrowed; NULL if unset). */
#define LAYOUT_SLOT(o, L, i) (*(PyObject **)((char *)(o) + (L)->offset[i]))

/* getattr(o, name): a new reference, or NULL with the exception set. */
static inline PyObject *get_attr(PyObject *o, PyObject *name)
{
    PyObject **p = slot_of(o, name);
    if (p != NULL && *p != NULL) {
        Py_INCREF(*p);
        return *p;
    }
    return PyObject_GetAttr(o, name);
}

/* setattr(o, name, v): 0, or -1 with the exception set. */
static inline int set_attr(PyObject *o, PyObject *name, PyObject *v)
{
    PyObject **p = slot_of(o, name);
    if (p == NULL)
        return PyObject_SetAttr(o, name, v);
    PyObject *old = *p;
    Py_INCREF(v);
    *p = v;
    Py_XDECREF(old);
    return 0;
}

/* An int attribute; on failure 0, with *err set and the exception pending. */
static inline long get_long(PyObject *o, PyObject *name, int *err)
{
    PyObject **p = slot_of(o, name);
    if (p != NULL && *p != NULL && PyLong_CheckExact(*p)) {
        int overflow;
        long x = PyLong_AsLongAndOverflow(*p, &overflow);
        if (!overflow)
            return x;
    }
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
    PyObject **p = slot_of(o, name);
    if (p != NULL && (*p == Py_True || *p == Py_False))
        return *p == Py_True;
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
    int rc = set_attr(o, name, v);
    Py_DECREF(v);
    return rc;
}

#endif
