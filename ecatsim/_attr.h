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

/* The offset of the plain __slots__ member ``name`` of type ``t``, or -1: not such a
 * member (Python's lookup then decides, errors included; no exception is left set). The
 * class attribute is the member descriptor (public API: the type's getattr and the
 * PyMemberDescr type). A type's slot offsets are fixed when it is created. */
static inline Py_ssize_t member_offset(PyTypeObject *t, PyObject *name)
{
    PyObject *d = PyObject_GetAttr((PyObject *)t, name);
    if (d == NULL) {
        PyErr_Clear();
        return -1;
    }
    Py_ssize_t off = -1;
    if (Py_IS_TYPE(d, &PyMemberDescr_Type)) {
        PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
        if (m->type == T_OBJECT_EX && !(m->flags & READONLY))
            off = m->offset;
    }
    Py_DECREF(d);
    return off;
}

/* Where a __slots__ attribute lives in an object, found once per (name, type) and kept:
 * the compiled paths read their state after a sleep, when every line is a cache miss,
 * and a slot read touches two lines where PyObject_GetAttr touches about ten. The cache
 * holds a reference to each type it knows, so that no other type can take its address. */
typedef struct {
    PyObject *name;
    PyTypeObject *type;
    Py_ssize_t offset; /* -1: not a plain slot */
} SlotCache;

#define SLOT_CACHE_SIZE 256
static SlotCache slot_cache[SLOT_CACHE_SIZE];

/* The slot of ``name`` in ``o``, or NULL: not a plain __slots__ member (Python's lookup
 * then decides, errors included). */
static inline PyObject **slot_of(PyObject *o, PyObject *name)
{
    PyTypeObject *t = Py_TYPE(o);
    SlotCache *c = &slot_cache[((uintptr_t)name >> 4) % SLOT_CACHE_SIZE];
    if (c->name != name || c->type != t) {
        Py_ssize_t off = member_offset(t, name);
        Py_INCREF(t);
        Py_XSETREF(c->type, t);
        c->name = name; /* interned at module init, never freed */
        c->offset = off;
    }
    return c->offset < 0 ? NULL : (PyObject **)((char *)o + c->offset);
}

/* The offsets of several __slots__ members of one type, found together: an object read
 * member by member through slot_of touches one cache entry per member; through a Layout
 * it touches one table. */
#define LAYOUT_MAX 24
typedef struct {
    PyTypeObject *type; /* a reference held; NULL: unknown */
    int n;
    int plain; /* every member a plain slot: offset[] holds */
    Py_ssize_t offset[LAYOUT_MAX];
} Layout;

/* 1: every one of names[:n] is a plain __slots__ member of o's type, their offsets in L;
 * 0: not (read them by name). */
static inline int layout_of(Layout *L, PyObject *o, PyObject *const *names, int n)
{
    PyTypeObject *t = Py_TYPE(o);
    if (L->type == t && L->n == n)
        return L->plain;
    int plain = n <= LAYOUT_MAX;
    for (int i = 0; plain && i < n; i++) {
        L->offset[i] = member_offset(t, names[i]);
        plain = L->offset[i] >= 0;
    }
    Py_INCREF(t);
    Py_XSETREF(L->type, t);
    L->n = n;
    L->plain = plain;
    return plain;
}

/* L holds for o: the members can be written at their offsets. */
static inline int layout_holds(const Layout *L, PyObject *o)
{
    return L->type == Py_TYPE(o) && L->plain;
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
