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
 * Ref: packet(7) (sll_pkttype, PACKET_AUXDATA), socket(7) (SO_TIMESTAMPNS);
 * IEEE 802.1Q; tests/unit/link/test_links.py runs both receive paths.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <errno.h>
#include <linux/if_packet.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>

#define ETH_P_8021Q 0x8100

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
    unsigned char *buf = view.buf;
    Py_ssize_t cap = view.len;
    long n = 0;
    long long stamp = 0;
    for (;;) {
        struct sockaddr_ll addr;
        union {
            struct cmsghdr align;
            char data[CMSG_SPACE(sizeof(struct tpacket_auxdata)) +
                      CMSG_SPACE(sizeof(struct timespec)) + 64];
        } control;
        struct iovec iov = {buf, (size_t)cap};
        struct msghdr msg;
        memset(&msg, 0, sizeof msg);
        msg.msg_name = &addr;
        msg.msg_namelen = sizeof addr;
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control.data;
        msg.msg_controllen = sizeof control.data;
        ssize_t got = recvmsg(fd, &msg, MSG_DONTWAIT);
        if (got < 0) {
            int e = errno;
            PyBuffer_Release(&view);
            if (e == EAGAIN || e == EWOULDBLOCK || e == EINTR || e == ENETDOWN)
                return Py_BuildValue("(iL)", 0, 0LL);
            errno = e;
            return PyErr_SetFromErrno(PyExc_OSError);
        }
        if (msg.msg_namelen >= sizeof addr - sizeof addr.sll_addr &&
            addr.sll_pkttype == PACKET_OUTGOING)
            continue;
        n = (long)got;
        stamp = 0;
        for (struct cmsghdr *c = CMSG_FIRSTHDR(&msg); c != NULL; c = CMSG_NXTHDR(&msg, c)) {
            if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS &&
                c->cmsg_len >= CMSG_LEN(sizeof(struct timespec))) {
                struct timespec ts;
                memcpy(&ts, CMSG_DATA(c), sizeof ts);
                stamp = (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
            } else if (c->cmsg_level == SOL_PACKET && c->cmsg_type == PACKET_AUXDATA &&
                       c->cmsg_len >= CMSG_LEN(sizeof(struct tpacket_auxdata))) {
                struct tpacket_auxdata aux;
                memcpy(&aux, CMSG_DATA(c), sizeof aux);
                if ((aux.tp_status & TP_STATUS_VLAN_VALID) && n >= 12 && n + 4 <= cap) {
                    unsigned tpid = (aux.tp_status & TP_STATUS_VLAN_TPID_VALID)
                                        ? aux.tp_vlan_tpid
                                        : ETH_P_8021Q;
                    memmove(buf + 16, buf + 12, (size_t)(n - 12));
                    buf[12] = (unsigned char)(tpid >> 8);
                    buf[13] = (unsigned char)tpid;
                    buf[14] = (unsigned char)(aux.tp_vlan_tci >> 8);
                    buf[15] = (unsigned char)aux.tp_vlan_tci;
                    n += 4;
                }
            }
        }
        break;
    }
    PyBuffer_Release(&view);
    return Py_BuildValue("(lL)", n, stamp);
}

static PyMethodDef methods[] = {
    {"recv", (PyCFunction)(void (*)(void))recv_frame, METH_FASTCALL,
     "recv(fd, buf) -> (n, stamp_ns): one EtherCAT frame from a RawLink socket."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_rawio", "Compiled receive of the raw link.", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__rawio(void) { return PyModule_Create(&module); }
