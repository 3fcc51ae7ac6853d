/* Compiled receive of RawLink (optional): one recvmsg(2) on the AF_PACKET socket, the
 * same work as RawLink._recv_py without what Python's socket module adds on this path:
 * the SIOCGIFNAME ioctl it makes for every packet to name the interface in the address
 * tuple, the ancillary-data list, and an exception when no frame is waiting.
 *
 * recv(fd, buf) -> (n, stamp_ns)
 *   n: frame length in buf (an 802.1Q tag the kernel moved into PACKET_AUXDATA put back
 *      at offset 12), 0 if no frame is waiting (EAGAIN, EINTR, ENETDOWN);
 *   stamp_ns: the SO_TIMESTAMPNS receive time stamp (CLOCK_REALTIME ns), 0 if none.
 *   Our own outgoing packets (PACKET_OUTGOING) are skipped. Other errors raise OSError.
 *
 * Ref: packet(7), socket(7); _rawio.h; tests/unit/link/test_links.py runs both receive
 * paths.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "../_module.h"
#include "_rawio.h"

static PyObject *recv_frame(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "recv(fd, buf) takes 2 arguments");
        return NULL;
    }
    int fd = (int)PyLong_AsLong(args[0]);
    if (fd == -1 && PyErr_Occurred())
        return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(args[1], &view, PyBUF_WRITABLE) < 0)
        return NULL;
    long long stamp = 0;
    long n = raw_recv(fd, view.buf, (long)view.len, MSG_DONTWAIT, &stamp);
    PyBuffer_Release(&view);
    if (n < 0) {
        errno = (int)-n;
        return PyErr_SetFromErrno(PyExc_OSError);
    }
    return Py_BuildValue("(lL)", n, stamp);
}

static PyMethodDef methods[] = {
    {"recv", (PyCFunction)(void (*)(void))recv_frame, METH_FASTCALL,
     "recv(fd, buf) -> (n, stamp_ns): one EtherCAT frame from a RawLink socket."},
    {NULL, NULL, 0, NULL},
};

static int exec_module(PyObject *m)
{
    (void)m;
    return 0;
}

static PyModuleDef_Slot slots[] = ECATSIM_MODULE_SLOTS(exec_module);

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_rawio", "Compiled receive of the raw link.", 0, methods,
    slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__rawio(void) { return PyModuleDef_Init(&module); }
