/* The compiled responder (optional, decision P9): the daemon's wait, receive, the
 * cyclic frame's walk and the send in one call, with no Python run between the frame's
 * arrival and its reply.
 *
 * The wait releases the GIL only when other Python threads exist.
 *
 * serve(fd, others, buf, rx_copy, deadline_ns, busy, seg, t_rx, timer_fd)
 *     -> (code, n, t_rx, p)
 *   fd: the RawLink socket; others: fds that end the wait when readable (wake pipe,
 *   control socket); buf, rx_copy: bytearrays of equal size; deadline_ns: host monotonic
 *   time at which the wait ends; busy: spin instead of sleeping in ppoll(2); seg: the
 *   Segment, or None to only wait and receive; t_rx: the frame's arrival time (host
 *   monotonic ns), 0: from the kernel's receive time stamp (tests give the time);
 *   timer_fd: from timer(), armed once per deadline and watched with the rest, or -1 (a
 *   ppoll timeout instead).
 *
 *   code TIMEOUT: the deadline came with no frame waiting.
 *        WAKE:    one of ``others`` is readable, or a signal came (its handler has run).
 *        FRAME:   a frame is in buf[:n], received at t_rx, untouched: Python serves it
 *                 (Daemon.handle_frame). Every frame this module does not serve whole goes
 *                 there before any state is changed (at most seg.irq is refreshed first,
 *                 as Segment._refresh would refresh it).
 *        REPLIED: the frame (as received: rx_copy[:n]) was processed and its reply sent.
 *        RESUME:  the datagrams before offset p are processed (rx_copy[:n] as received);
 *                 Segment.resume walks the rest and Python replies.
 *
 * Served here: frames whose datagrams are LRD/LWR/LRW (through logical_run, _logical.h)
 * or NOP, the last one possibly an FRMW of 0x0910 (4 or 8 bytes, at most one reader): the
 * DC time distribution of every cyclic frame. The reference's read is the system time
 * of DcUnit.refresh_system_time; the writers' time loops are left pending for
 * Segment.after_reply, as Segment._frmw_system_time does (decision P7). Everything else
 * (the segment's state not settled, a SYNC pulse that may be due, other commands, a
 * malformed frame) is FRAME. The Python path (Daemon.handle_frame, Segment.process) is
 * the reference: tests/unit/test_serve.py runs both on the same frames.
 *
 * Ref: ETG.1000.4 §5.3-5.4 (frame, datagrams, WKC), Table 12 (FRMW); TMC8460 §5.50.2
 * Table 95 (system time); ppoll(2), packet(7); docs/decisions.md P1, P7, P9.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <poll.h>
#include <sched.h>
#include <stdint.h>
#include <string.h>
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

#include "_module.h"
#include "esc/_logical.h"
#include "esc/_windows.h"
#include "link/_rawio.h"

enum { TIMEOUT = 0, WAKE = 1, FRAME = 2, REPLIED = 3, RESUME = 4 };

/* EtherCAT frame and datagram layout (ecatsim/wire/frame.py, datagram.py). */
#define ETH_HEADER_LEN 14
#define VLAN_TAG_LEN 4
#define ECAT_HEADER_LEN 2
#define ETHERTYPE_ECAT 0x88A4
#define ETHERTYPE_VLAN 0x8100
#define DG_HEADER_LEN 10
#define LEN_MASK 0x07FF
#define MORE_FOLLOWS 0x8000
#define NOP 0x00
#define FRMW 0x0E
/* DC registers (ecatsim/esc/regs.py). Ref: TMC8460 §5.50.2 Tables 95-96. */
#define DC_SYSTEM_TIME 0x0910
#define DC_SYSTEM_TIME_OFFSET 0x0920
#define MAX_WATCH 8
#define MAX_TIMER_FD 4096
/* a receive time stamp older than this: the wall clock was stepped (raw.py MAX_RX_AGE_NS) */
#define MAX_RX_AGE_NS 1000000000LL
/* busy mode: spins between two looks at ``others`` */
#define BUSY_SPINS 64

static PyObject *s_logical, *s_reach, *s_irq, *s_port0_closed, *s_pulse_hint, *s_dc_pending,
    *s_dc_reader, *s_dc_reach, *s_dc_before, *s_dc_after, *s_addr_map, *s_escs, *s_frames,
    *s_frame_no, *s_topology_dirty, *s_addr_dirty, *s_logical_dirty,
    *s_timers_dirty, *s_dc, *s_local_ref, *s_t_ref, *s_spd, *s_hop_ns, *s_sm_windows;

static long long clock_ns(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* RawLink.recv_into + Daemon: the frame's host monotonic time from its CLOCK_REALTIME
 * receive stamp (raw.py _monotonic), else now. */
static long long rx_time(long long stamp)
{
    if (stamp) {
        long long age = clock_ns(CLOCK_REALTIME) - stamp;
        if (age >= 0 && age < MAX_RX_AGE_NS)
            return clock_ns(CLOCK_MONOTONIC) - age;
    }
    return clock_ns(CLOCK_MONOTONIC);
}

static inline uint64_t rd64(const uint8_t *m, long a)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--)
        v = (v << 8) | m[a + i];
    return v;
}

static inline void wr64(uint8_t *m, long a, uint64_t v)
{
    for (int i = 0; i < 8; i++)
        m[a + i] = (uint8_t)(v >> (8 * i));
}

/* An attribute that must be a bytearray of at least ``size`` bytes (new reference). */
static PyObject *get_bytearray(PyObject *o, PyObject *name, Py_ssize_t size)
{
    PyObject *v = get_attr(o, name);
    if (v != NULL && (!PyByteArray_Check(v) || PyByteArray_GET_SIZE(v) < size)) {
        Py_DECREF(v);
        PyErr_SetString(PyExc_TypeError, "expected a bytearray");
        return NULL;
    }
    return v;
}

/* The reference clock of an FRMW of 0x0910, resolved before anything changes. */
typedef struct {
    Py_ssize_t reader; /* position of the reader in the walk; == reach: none */
    PyObject *esc;     /* borrowed from Segment.escs; NULL: none */
} Frmw;

/* Segment._frmw_system_time's conditions for the reference: the FP address names at most
 * one slave, and its 0x0910 is a plain register (no SM window over it). 1 yes, 0 no
 * (FRAME), -1 error. */
static int frmw_resolve(PyObject *seg, unsigned adp, long dlen, long reach, Frmw *f)
{
    PyObject *amap = get_attr(seg, s_addr_map);
    if (amap == NULL)
        return -1;
    PyObject *key = PyLong_FromLong((long)adp);
    PyObject *readers = key == NULL ? NULL : PyDict_GetItemWithError(amap, key);
    Py_XDECREF(key);
    int ok = 1;
    f->reader = reach;
    f->esc = NULL;
    if (readers == NULL) {
        ok = PyErr_Occurred() ? -1 : 1; /* nobody answers to adp: every slave writes */
    } else if (!PyTuple_Check(readers) || PyTuple_GET_SIZE(readers) > 1) {
        ok = 0;
    } else if (PyTuple_GET_SIZE(readers) == 1) {
        long r = PyLong_AsLong(PyTuple_GET_ITEM(readers, 0));
        if (r == -1 && PyErr_Occurred())
            ok = -1;
        else
            f->reader = r;
    }
    Py_DECREF(amap);
    if (ok <= 0 || f->reader >= reach)
        return ok;
    PyObject *escs = get_attr(seg, s_escs);
    if (escs == NULL)
        return -1;
    if (!PyList_Check(escs) || f->reader < 0 || f->reader >= PyList_GET_SIZE(escs)) {
        Py_DECREF(escs);
        return 0;
    }
    f->esc = PyList_GET_ITEM(escs, f->reader);
    Py_DECREF(escs); /* the segment keeps the list and the ESC */
    /* a window over 0x0910: Esc.ecat_read would go to the SM */
    return no_sm_window(f->esc, s_sm_windows, DC_SYSTEM_TIME, DC_SYSTEM_TIME + dlen);
}

/* DcUnit.refresh_system_time at the frame's time, then the read of 0x0910 into data:
 * local_ref + int((t_arrival - t_ref) * spd) + offset 0x0920, modulo 2^64, where
 * t_arrival = t_ns + position * hop_ns (DcUnit.arrival_ns).
 * Ref: TMC8460 §5.50.2 Table 95, §5.50.3 Table 96. */
static int system_time_read(PyObject *esc, long long t_ns, uint8_t *data, long dlen)
{
    PyObject *dc = get_attr(esc, s_dc);
    if (dc == NULL)
        return -1;
    PyObject *mem = get_bytearray(esc, s_mem, MEM_SIZE);
    PyObject *lref = get_attr(dc, s_local_ref);
    PyObject *tref = get_attr(dc, s_t_ref);
    PyObject *spdo = get_attr(dc, s_spd);
    int err = 0;
    long position = get_long(dc, s_position, &err);
    long hop = get_long(dc, s_hop_ns, &err);
    int rc = -1;
    if (mem != NULL && lref != NULL && tref != NULL && spdo != NULL && !err) {
        uint64_t local_ref = PyLong_AsUnsignedLongLongMask(lref);
        long long t_ref = PyLong_AsLongLong(tref);
        double spd = PyFloat_AsDouble(spdo);
        if (!PyErr_Occurred()) {
            long long t_arr = t_ns + (long long)position * hop;
            uint64_t local = local_ref + (uint64_t)(long long)((double)(t_arr - t_ref) * spd);
            uint8_t *m = (uint8_t *)PyByteArray_AS_STRING(mem);
            wr64(m, DC_SYSTEM_TIME, local + rd64(m, DC_SYSTEM_TIME_OFFSET));
            memcpy(data, m + DC_SYSTEM_TIME, (size_t)dlen);
            rc = 0;
        }
    }
    Py_XDECREF(dc);
    Py_XDECREF(mem);
    Py_XDECREF(lref);
    Py_XDECREF(tref);
    Py_XDECREF(spdo);
    return rc;
}

/* Segment._frmw_system_time: the reference reads, the writers' data is kept for
 * Segment.after_reply. WKC: +1 per slave reached (the read and every write count). */
static int frmw_system_time(PyObject *seg, const Frmw *f, long long t_ns, uint8_t *data,
                            long dlen, long reach)
{
    PyObject *before = get_bytearray(seg, s_dc_before, dlen);
    PyObject *after = before == NULL ? NULL : get_bytearray(seg, s_dc_after, dlen);
    int rc = after == NULL ? -1 : 0;
    if (rc == 0 && f->reader > 0)
        memcpy(PyByteArray_AS_STRING(before), data, (size_t)dlen);
    if (rc == 0 && f->esc != NULL)
        rc = system_time_read(f->esc, t_ns, data, dlen);
    if (rc == 0 && f->reader + 1 < reach)
        memcpy(PyByteArray_AS_STRING(after), data, (size_t)dlen);
    Py_XDECREF(before);
    Py_XDECREF(after);
    if (rc == 0 && (set_long(seg, s_dc_pending, dlen) < 0 ||
                    set_long(seg, s_dc_reader, f->reader) < 0 ||
                    set_long(seg, s_dc_reach, reach) < 0))
        rc = -1;
    return rc;
}

/* Offset of the EtherCAT header (wire/frame.py ecat_offset), -1: not EtherCAT. */
static long ecat_offset(const uint8_t *b, long n)
{
    if (n < ETH_HEADER_LEN + ECAT_HEADER_LEN)
        return -1;
    unsigned et = ((unsigned)b[12] << 8) | b[13];
    if (et == ETHERTYPE_ECAT)
        return ETH_HEADER_LEN;
    if (et == ETHERTYPE_VLAN && n >= ETH_HEADER_LEN + VLAN_TAG_LEN + ECAT_HEADER_LEN &&
        (((unsigned)b[16] << 8) | b[17]) == ETHERTYPE_ECAT)
        return ETH_HEADER_LEN + VLAN_TAG_LEN;
    return -1;
}

/* The segment's tables to refresh (Segment._refresh): topology, addresses or logical
 * maps (1: Python refreshes them), or the IRQ field, refreshed here: seg.irq = OR of
 * ecat_irq over the slaves reached. 0: settled; -1: error. */
static int settle(PyObject *seg, PyObject *ctx, long reach, long *irq, int with_timers)
{
    int err = 0;
    int d = get_bool(ctx, s_topology_dirty, &err) || get_bool(ctx, s_addr_dirty, &err) ||
            get_bool(ctx, s_logical_dirty, &err) ||
            (with_timers && get_bool(ctx, s_timers_dirty, &err));
    if (err)
        return -1;
    if (d)
        return 1;
    if (!get_bool(ctx, s_irq_dirty, &err))
        return err ? -1 : 0;
    PyObject *escs = get_attr(seg, s_escs);
    if (escs == NULL)
        return -1;
    if (!PyList_Check(escs) || PyList_GET_SIZE(escs) < reach) {
        Py_DECREF(escs);
        return 1;
    }
    long v = 0;
    for (long i = 0; i < reach && !err; i++)
        v |= get_long(PyList_GET_ITEM(escs, i), s_ecat_irq, &err);
    Py_DECREF(escs);
    if (err || set_attr(ctx, s_irq_dirty, Py_False) < 0 || set_long(seg, s_irq, v) < 0)
        return -1;
    *irq = v;
    return 0;
}

/* The frame's result: (code, n, t_rx, p). */
static PyObject *result(int code, long n, long long t_rx, long p)
{
    return Py_BuildValue("(ilLl)", code, n, t_rx, p);
}

/* Segment.process + _walk for a frame served whole here: REPLIED (after the send),
 * FRAME (nothing changed), RESUME (at *p), -1 error. */
static int walk(PyObject *seg, uint8_t *b, long n, long long t_rx, long *p_out)
{
    long off = ecat_offset(b, n);
    if (off < 0 || off + ECAT_HEADER_LEN > n)
        return FRAME;
    unsigned hdr = b[off] | (b[off + 1] << 8);
    long end = off + ECAT_HEADER_LEN + (hdr & LEN_MASK);
    if ((hdr >> 12) != 1 || end > n)
        return FRAME;
    PyObject *ctx = get_attr(seg, s_ctx);
    if (ctx == NULL)
        return -1;
    int err = 0;
    long long hint = 0;
    long reach = get_long(seg, s_reach, &err), irq = get_long(seg, s_irq, &err);
    long dc_pending = get_long(seg, s_dc_pending, &err);
    int closed = get_bool(seg, s_port0_closed, &err);
    PyObject *hinto = err ? NULL : get_attr(seg, s_pulse_hint);
    if (hinto != NULL) {
        hint = PyLong_AsLongLong(hinto);
        Py_DECREF(hinto);
    }
    int dirty = err || PyErr_Occurred() ? -1 : settle(seg, ctx, reach, &irq, 1);
    int rc = FRAME;
    if (dirty < 0) {
        rc = -1;
        goto done;
    }
    /* Segment.process: the previous frame's work, a pulse that may be due, the segment's
     * tables to refresh, no slave reached, the port-0 loop closed: all in Python */
    if (dirty || dc_pending || t_rx >= hint || reach <= 0 || closed)
        goto done;
    /* the datagram chain, as Segment.process validates it, and what each one is */
    Frmw frmw = {reach, NULL};
    long p = off + ECAT_HEADER_LEN;
    for (;;) {
        if (p + DG_HEADER_LEN + 2 > end)
            goto done;
        unsigned cmd = b[p], lf = b[p + 6] | (b[p + 7] << 8);
        long q = p + DG_HEADER_LEN + 2 + (lf & LEN_MASK);
        if (q > end)
            goto done;
        long dlen = lf & LEN_MASK;
        if (cmd == FRMW) {
            unsigned ado = b[p + 4] | (b[p + 5] << 8);
            if (ado != DC_SYSTEM_TIME || (lf & MORE_FOLLOWS) || (dlen != 4 && dlen != 8))
                goto done;
            int ok = frmw_resolve(seg, b[p + 2] | (b[p + 3] << 8), dlen, reach, &frmw);
            if (ok <= 0) {
                rc = ok < 0 ? -1 : FRAME;
                goto done;
            }
        } else if (cmd != LRD && cmd != LWR && cmd != LRW && cmd != NOP) {
            goto done;
        }
        if (!(lf & MORE_FOLLOWS))
            break;
        p = q;
    }
    /* Segment.process's bookkeeping, then the walk */
    long frame_no = get_long(ctx, s_frame_no, &err), frames = get_long(seg, s_frames, &err);
    if (err || set_long(ctx, s_frame_no, frame_no + 1) < 0 || set_long(ctx, s_t_ns, t_rx) < 0 ||
        set_long(seg, s_frames, frames + 1) < 0) {
        rc = -1;
        goto done;
    }
    PyObject *logical = get_attr(seg, s_logical);
    if (logical == NULL || !PyList_Check(logical)) {
        if (logical != NULL)
            PyErr_SetString(PyExc_TypeError, "Segment.logical must be a list");
        Py_XDECREF(logical);
        rc = -1;
        goto done;
    }
    p = off + ECAT_HEADER_LEN;
    for (;;) {
        unsigned cmd = b[p], lf = b[p + 6] | (b[p + 7] << 8);
        long dlen = lf & LEN_MASK, d0 = p + DG_HEADER_LEN, w = d0 + dlen;
        long inc = 0;
        if (cmd == FRMW) {
            if (frmw_system_time(seg, &frmw, t_rx, b + d0, dlen, reach) < 0)
                inc = LOGICAL_ERROR;
            else
                inc = reach;
        } else if (cmd != NOP) {
            long long lad = (long long)(b[p + 2] | (b[p + 3] << 8)) |
                            ((long long)(b[p + 4] | (b[p + 5] << 8)) << 16);
            inc = logical_run(logical, (long)cmd, lad, b + d0, dlen);
        }
        if (inc == LOGICAL_ERROR || inc == LOGICAL_DECLINED) {
            rc = inc == LOGICAL_ERROR ? -1 : RESUME;
            *p_out = p;
            break;
        }
        if (cmd != NOP) {
            b[p + 8] |= (uint8_t)irq;
            b[p + 9] |= (uint8_t)(irq >> 8);
            if (inc) {
                unsigned wkc = (b[w] | (b[w + 1] << 8)) + (unsigned)inc;
                b[w] = (uint8_t)wkc;
                b[w + 1] = (uint8_t)(wkc >> 8);
            }
        }
        if (!(lf & MORE_FOLLOWS)) {
            rc = REPLIED;
            break;
        }
        p = w + 2;
        dirty = settle(seg, ctx, reach, &irq, 0); /* as Segment._walk, between datagrams */
        if (dirty) {
            rc = dirty < 0 ? -1 : RESUME;
            *p_out = p;
            break;
        }
    }
    Py_DECREF(logical);
done:
    Py_DECREF(ctx);
    return rc;
}

/* The deadline each timer fd (from timer()) is armed for; -1: not armed. */
static long long armed[MAX_TIMER_FD];

/* Arm timer fd ``tfd`` for ``deadline`` (absolute, CLOCK_MONOTONIC) unless it already is:
 * the kernel's timer is programmed once per deadline, not once per wait. -1 on error. */
static int arm(int tfd, long long deadline)
{
    if (armed[tfd] == deadline)
        return 0;
    struct itimerspec its;
    memset(&its, 0, sizeof its);
    its.it_value.tv_sec = (time_t)(deadline / 1000000000LL);
    its.it_value.tv_nsec = (long)(deadline % 1000000000LL);
    if (its.it_value.tv_sec == 0 && its.it_value.tv_nsec == 0)
        its.it_value.tv_nsec = 1; /* all zero would disarm it */
    if (timerfd_settime(tfd, TFD_TIMER_ABSTIME, &its, NULL) < 0)
        return -1;
    armed[tfd] = deadline;
    return 0;
}

/* Another Python thread exists: the wait releases the GIL for it. The daemon has none,
 * and taking the GIL back after the wake-up costs microseconds per frame (P9). No
 * thread can start while this one blocks holding the GIL. */
static int other_threads(void)
{
    PyThreadState *me = PyThreadState_Get();
    PyThreadState *t = PyInterpreterState_ThreadHead(PyThreadState_GetInterpreter(me));
    return t != NULL && (t != me || PyThreadState_Next(t) != NULL);
}

/* ppoll(2), with the GIL released only if another Python thread could use it. */
static int wait_fds(struct pollfd *pfd, nfds_t n, const struct timespec *ts)
{
    int rc;
    if (!other_threads())
        return ppoll(pfd, n, ts, NULL);
    Py_BEGIN_ALLOW_THREADS
    rc = ppoll(pfd, n, ts, NULL);
    Py_END_ALLOW_THREADS
    return rc;
}

/* Wait for a frame (or the deadline, or ``others``) and receive it: n > 0, or -code.
 * pfd: the link, ``others``, then the timer fd if tfd >= 0. With a timer fd the wait has
 * no timeout of its own: ppoll(2) with a timeout arms and cancels a kernel timer on every
 * call, a timer reprogramming that is costly in a VM (decision P9). */
static long wait_frame(int fd, struct pollfd *pfd, int nothers, int tfd, uint8_t *buf,
                       long cap, long long deadline, int busy, long long *stamp)
{
    for (int spin = 0;; spin++) {
        long n = raw_recv(fd, buf, cap, MSG_DONTWAIT, stamp);
        if (n > 0)
            return n;
        if (n < 0) {
            errno = (int)-n;
            PyErr_SetFromErrno(PyExc_OSError);
            return -1000;
        }
        if (PyErr_CheckSignals() < 0)
            return -1000;
        long long left = deadline - clock_ns(CLOCK_MONOTONIC);
        if (left <= 0)
            return -TIMEOUT;
        int rc;
        if (busy) {
            if (spin % BUSY_SPINS || nothers == 0)
                continue;
            rc = poll(pfd + 1, (nfds_t)nothers, 0);
        } else if (tfd >= 0) {
            if (arm(tfd, deadline) < 0) {
                PyErr_SetFromErrno(PyExc_OSError);
                return -1000;
            }
            rc = wait_fds(pfd, (nfds_t)(nothers + 2), NULL);
            if (rc > 0 && pfd[nothers + 1].revents) {
                uint64_t expirations;
                if (read(tfd, &expirations, sizeof expirations) < 0 && errno != EAGAIN) {
                    PyErr_SetFromErrno(PyExc_OSError);
                    return -1000;
                }
            }
        } else {
            struct timespec ts = {(time_t)(left / 1000000000LL), (long)(left % 1000000000LL)};
            rc = wait_fds(pfd, (nfds_t)(nothers + 1), &ts);
        }
        if (rc < 0) {
            if (errno != EINTR) {
                PyErr_SetFromErrno(PyExc_OSError);
                return -1000;
            }
            if (PyErr_CheckSignals() < 0)
                return -1000;
            return -WAKE; /* a handler ran: the loop looks at its stop flag */
        }
        for (int i = 1; i <= nothers; i++)
            if (pfd[i].revents)
                return -WAKE;
    }
}

/* timer() -> fd: a timer fd for serve()'s deadlines (the caller closes it). */
static PyObject *timer(PyObject *self, PyObject *noargs)
{
    (void)self;
    (void)noargs;
    int tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (tfd < 0)
        return PyErr_SetFromErrno(PyExc_OSError);
    if (tfd >= MAX_TIMER_FD) {
        close(tfd);
        PyErr_SetString(PyExc_OSError, "timer fd number too large");
        return NULL;
    }
    armed[tfd] = -1;
    return PyLong_FromLong(tfd);
}

static PyObject *serve(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 9 || !PyTuple_Check(args[1]) || !PyByteArray_Check(args[2]) ||
        !PyByteArray_Check(args[3]) ||
        PyByteArray_GET_SIZE(args[3]) < PyByteArray_GET_SIZE(args[2])) {
        PyErr_SetString(PyExc_TypeError,
                        "serve(fd, others: tuple, buf: bytearray, rx_copy: bytearray, "
                        "deadline_ns, busy, seg, t_rx, timer_fd)");
        return NULL;
    }
    int fd = (int)PyLong_AsLong(args[0]);
    long long deadline = PyLong_AsLongLong(args[4]);
    int busy = PyObject_IsTrue(args[5]);
    long long t_given = PyLong_AsLongLong(args[7]);
    int tfd = (int)PyLong_AsLong(args[8]);
    if (PyErr_Occurred() || busy < 0)
        return NULL;
    if (tfd >= MAX_TIMER_FD) {
        PyErr_SetString(PyExc_ValueError, "timer_fd: not from timer()");
        return NULL;
    }
    PyObject *seg = args[6];
    struct pollfd pfd[MAX_WATCH + 2];
    Py_ssize_t nothers = PyTuple_GET_SIZE(args[1]);
    if (nothers > MAX_WATCH) {
        PyErr_SetString(PyExc_ValueError, "too many fds to watch");
        return NULL;
    }
    pfd[0].fd = fd;
    pfd[0].events = POLLIN;
    for (Py_ssize_t i = 0; i < nothers; i++) {
        pfd[i + 1].fd = (int)PyLong_AsLong(PyTuple_GET_ITEM(args[1], i));
        pfd[i + 1].events = POLLIN;
        pfd[i + 1].revents = 0;
    }
    pfd[nothers + 1].fd = tfd;
    pfd[nothers + 1].events = POLLIN;
    pfd[nothers + 1].revents = 0;
    if (PyErr_Occurred())
        return NULL;
    uint8_t *buf = (uint8_t *)PyByteArray_AS_STRING(args[2]);
    long cap = (long)PyByteArray_GET_SIZE(args[2]);
    long long stamp = 0;
    long n = wait_frame(fd, pfd, (int)nothers, tfd, buf, cap, deadline, busy, &stamp);
    if (n == -1000)
        return NULL;
    if (n <= 0)
        return result((int)-n, 0, 0, 0);
    long long t_rx = t_given ? t_given : rx_time(stamp);
    if (seg == Py_None)
        return result(FRAME, n, t_rx, 0);
    memcpy(PyByteArray_AS_STRING(args[3]), buf, (size_t)n);
    long p = 0;
    int rc = walk(seg, buf, n, t_rx, &p);
    if (rc < 0)
        return NULL;
    if (rc == REPLIED) {
        buf[6] |= 0x02; /* processed (wire/frame.py mark_processed) */
        if (send(fd, buf, (size_t)n, 0) < 0 && errno != ENOBUFS && errno != EAGAIN &&
            errno != ENETDOWN && errno != ENXIO)
            return PyErr_SetFromErrno(PyExc_OSError);
        sched_yield(); /* a master woken on this CPU takes the reply first (Daemon) */
    }
    return result(rc, n, t_rx, p);
}

/* slot_offset(obj, name) -> the offset slot_of reads ``name`` at in ``obj``, or -1 (read
 * by name): the tests see that the slot path engages on every interpreter. */
static PyObject *slot_offset(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *obj, *name;
    if (!PyArg_ParseTuple(args, "OU", &obj, &name))
        return NULL;
    Py_INCREF(name);
    PyUnicode_InternInPlace(&name);
    PyObject **p = slot_of(obj, name);
    long off = p == NULL ? -1 : (long)((char *)p - (char *)obj);
    /* the cache keeps the name: it stays alive (interned names are shared) */
    return PyLong_FromLong(off);
}

static PyMethodDef methods[] = {
    {"slot_offset", slot_offset, METH_VARARGS,
     "slot_offset(obj, name) -> int: where the compiled paths read obj.name (-1: by name)."},
    {"serve", (PyCFunction)(void (*)(void))serve, METH_FASTCALL,
     "serve(fd, others, buf, rx_copy, deadline_ns, busy, seg, t_rx, timer_fd) -> "
     "(code, n, t_rx, p)."},
    {"timer", timer, METH_NOARGS, "timer() -> fd: a timer fd for serve()'s deadlines."},
    {NULL, NULL, 0, NULL},
};

static int exec_module(PyObject *m)
{
    static const Name names[] = {
        {&s_logical, "logical"}, {&s_reach, "reach"}, {&s_irq, "irq"},
        {&s_port0_closed, "port0_closed"}, {&s_pulse_hint, "_pulse_hint"},
        {&s_dc_pending, "_dc_pending"}, {&s_dc_reader, "_dc_reader"},
        {&s_dc_reach, "_dc_reach"}, {&s_dc_before, "_dc_before"}, {&s_dc_after, "_dc_after"},
        {&s_addr_map, "addr_map"}, {&s_escs, "escs"}, {&s_frames, "frames"},
        {&s_frame_no, "frame_no"}, {&s_topology_dirty, "topology_dirty"},
        {&s_addr_dirty, "addr_dirty"}, {&s_logical_dirty, "logical_dirty"},
        {&s_timers_dirty, "timers_dirty"}, {&s_dc, "dc"}, {&s_local_ref, "local_ref"},
        {&s_t_ref, "t_ref"}, {&s_spd, "spd"}, {&s_hop_ns, "hop_ns"},
        {&s_sm_windows, "sm_windows"},
    };
    if (intern_names(names, sizeof names / sizeof names[0]) < 0 || logical_init() < 0)
        return -1;
    if (PyModule_AddIntConstant(m, "TIMEOUT", TIMEOUT) < 0 ||
        PyModule_AddIntConstant(m, "WAKE", WAKE) < 0 ||
        PyModule_AddIntConstant(m, "FRAME", FRAME) < 0 ||
        PyModule_AddIntConstant(m, "REPLIED", REPLIED) < 0 ||
        PyModule_AddIntConstant(m, "RESUME", RESUME) < 0)
        return -1;
    return 0;
}

static PyModuleDef_Slot slots[] = ECATSIM_MODULE_SLOTS(exec_module);

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_serve", "The compiled responder (decision P9).", 0, methods,
    slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__serve(void) { return PyModuleDef_Init(&module); }
