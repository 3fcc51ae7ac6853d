# cython: language_level=3
"""The daemon's compiled responder (decision P9): the wait, the receive of one frame with
its kernel time stamp, and the send of its reply in one call, with no Python bytecode run
between the frame's arrival and its reply but the segment's own (compiled) walk.

What happens to the frame is :meth:`Daemon.handle_frame`'s, through the same calls:
``Segment.pulses_due`` fires the SYNC pulses due before it and ``Segment.process`` walks it
(ETG.1000.4 §5.3-5.4); the frame as received is copied for the recorder, which Python
fills after the reply. Only the I/O is here: ppoll(2) (or a busy spin) on the raw socket,
the other descriptors and a timerfd_create(2) timer armed once per deadline; recvmsg(2) on
the packet(7) socket with its SO_TIMESTAMPNS receive time (socket(7)) and the 802.1Q tag
from PACKET_AUXDATA, as ``RawLink.recv_into`` receives (ecatsim/link/raw.py); send(2) as
``RawLink.send``. Nothing interpreted runs before the reply is sent.

Compiled only (no ``.py`` twin): where it is not built the daemon's select(2) loop serves.
"""

from cpython.exc cimport PyErr_CheckSignals, PyErr_SetFromErrno
from cpython.pystate cimport PyInterpreterState, PyThreadState
from libc.errno cimport EAGAIN, EINTR, ENETDOWN, ENOBUFS, ENXIO, errno
from libc.stdint cimport uint8_t, uint16_t, uint32_t, uint64_t
from libc.string cimport memcpy, memmove, memset
from posix.time cimport CLOCK_MONOTONIC, CLOCK_REALTIME, clock_gettime, timespec
from posix.types cimport time_t
from posix.uio cimport iovec
from posix.unistd cimport close, read

from ecatsim.wire.frame cimport ecat_offset, mark_processed

from os import strerror


cdef extern from "Python.h":
    PyThreadState *PyThreadState_Get()
    PyInterpreterState *PyThreadState_GetInterpreter(PyThreadState *)
    PyThreadState *PyInterpreterState_ThreadHead(PyInterpreterState *)
    PyThreadState *PyThreadState_Next(PyThreadState *)


cdef extern from "<poll.h>" nogil:
    ctypedef unsigned long nfds_t
    struct pollfd:
        int fd
        short events
        short revents
    enum: POLLIN
    int poll(pollfd *fds, nfds_t nfds, int timeout)
    int ppoll(pollfd *fds, nfds_t nfds, const timespec *tmo, const void *sigmask)


cdef extern from "<sched.h>" nogil:
    int sched_yield()


cdef extern from "<sys/timerfd.h>" nogil:
    struct itimerspec:
        timespec it_interval
        timespec it_value
    enum: TFD_NONBLOCK
    enum: TFD_CLOEXEC
    enum: TFD_TIMER_ABSTIME
    int timerfd_create(int clockid, int flags)
    int timerfd_settime(int fd, int flags, const itimerspec *new, itimerspec *old)


cdef extern from "<sys/socket.h>" nogil:
    ctypedef unsigned int socklen_t
    struct msghdr:
        void *msg_name
        socklen_t msg_namelen
        iovec *msg_iov
        size_t msg_iovlen
        void *msg_control
        size_t msg_controllen
        int msg_flags
    struct cmsghdr:
        size_t cmsg_len
        int cmsg_level
        int cmsg_type
    enum: SOL_SOCKET
    enum: SOL_PACKET
    enum: SCM_TIMESTAMPNS
    enum: MSG_DONTWAIT
    cmsghdr *CMSG_FIRSTHDR(msghdr *msg)
    cmsghdr *CMSG_NXTHDR(msghdr *msg, cmsghdr *cmsg)
    unsigned char *CMSG_DATA(cmsghdr *cmsg)
    size_t CMSG_LEN(size_t length)
    ssize_t recvmsg(int fd, msghdr *msg, int flags)
    ssize_t send(int fd, const void *buf, size_t n, int flags)


cdef extern from "<linux/if_packet.h>" nogil:
    struct sockaddr_ll:
        unsigned short sll_family
        unsigned char sll_pkttype
        unsigned char sll_addr[8]
    struct tpacket_auxdata:
        uint32_t tp_status
        uint16_t tp_vlan_tci
        uint16_t tp_vlan_tpid
    enum: PACKET_OUTGOING
    enum: PACKET_AUXDATA
    enum: TP_STATUS_VLAN_VALID
    enum: TP_STATUS_VLAN_TPID_VALID


#: serve()'s codes
cpdef enum:
    TIMEOUT = 0  # the deadline came with no frame waiting
    WAKE = 1  # one of ``others`` is readable, or a signal came (its handler has run)
    FRAME = 2  # a frame is in buf[:n], untouched: Python serves it (Daemon.handle_frame)
    REPLIED = 3  # the frame was processed and its reply sent
    DROPPED = 4  # the frame was processed and destroyed (Segment.process returned False)

cdef enum:
    #: the fds ``others`` may hold besides the link's
    MAX_WATCH = 8
    #: timer fds numbered below this (the ``armed`` table)
    MAX_TIMER_FD = 4096
    #: busy mode: spins between two looks at ``others``
    BUSY_SPINS = 64
    #: recvmsg(2)'s control buffer in 8-byte words (PACKET_AUXDATA and SO_TIMESTAMPNS)
    CONTROL_WORDS = 32
    #: a receive time stamp older than this: the wall clock was stepped (raw.py)
    MAX_RX_AGE_NS = 1_000_000_000
    ETH_P_8021Q = 0x8100
    #: an error was raised (the Python error indicator is set)
    ERROR = -1000

#: the deadline each timer fd (from timer()) is armed for; -1: not armed
cdef long long armed[MAX_TIMER_FD]


class SegmentError(Exception):
    """``Segment.pulses_due`` or ``Segment.process`` raised on a frame (the cause): the
    frame's failure, told apart from a failure of the socket (an OSError of serve()).
    ``args[0]``: the frame's length (it is in rx_copy as received)."""


cdef long long clock_ns(int clock_id) noexcept nogil:
    cdef timespec ts
    clock_gettime(clock_id, &ts)
    return <long long>ts.tv_sec * 1_000_000_000 + ts.tv_nsec


cdef long long rx_time(long long stamp) noexcept nogil:
    """The frame's host monotonic time from its CLOCK_REALTIME receive stamp: now minus
    its age (ecatsim/link/raw.py ``_monotonic``), else now."""
    cdef long long age
    if stamp:
        age = clock_ns(CLOCK_REALTIME) - stamp
        if 0 <= age < MAX_RX_AGE_NS:
            return clock_ns(CLOCK_MONOTONIC) - age
    return clock_ns(CLOCK_MONOTONIC)


cdef long raw_recv(int fd, uint8_t *buf, long cap, long long *stamp) noexcept nogil:
    """One frame by recvmsg(2) without blocking: its length (an 802.1Q tag the kernel
    moved into PACKET_AUXDATA put back at offset 12), 0 if none is waiting (EAGAIN,
    EINTR, ENETDOWN), -errno on another error. ``*stamp``: the SO_TIMESTAMPNS time
    (CLOCK_REALTIME ns), 0 if none. Our own outgoing frames are skipped.
    Ref: packet(7) (sll_pkttype, PACKET_AUXDATA), socket(7) (SO_TIMESTAMPNS); IEEE 802.1Q;
    RawLink.recv_into is the reference."""
    cdef sockaddr_ll addr
    cdef uint64_t control[CONTROL_WORDS]
    cdef iovec iov
    cdef msghdr msg
    cdef cmsghdr *c
    cdef timespec ts
    cdef tpacket_auxdata aux
    cdef ssize_t got
    cdef long n
    cdef unsigned tpid
    while True:
        iov.iov_base = buf
        iov.iov_len = <size_t>cap
        memset(&msg, 0, sizeof(msg))
        msg.msg_name = &addr
        msg.msg_namelen = sizeof(addr)
        msg.msg_iov = &iov
        msg.msg_iovlen = 1
        msg.msg_control = control
        msg.msg_controllen = sizeof(control)
        got = recvmsg(fd, &msg, MSG_DONTWAIT)
        stamp[0] = 0
        if got < 0:
            if errno == EAGAIN or errno == EINTR or errno == ENETDOWN:  # EWOULDBLOCK == EAGAIN
                return 0
            return -errno
        if msg.msg_namelen >= sizeof(addr) - sizeof(addr.sll_addr) and (
            addr.sll_pkttype == PACKET_OUTGOING
        ):
            continue
        n = <long>got
        c = CMSG_FIRSTHDR(&msg)
        while c != NULL:
            if (c.cmsg_level == SOL_SOCKET and c.cmsg_type == SCM_TIMESTAMPNS
                    and c.cmsg_len >= CMSG_LEN(sizeof(timespec))):
                memcpy(&ts, CMSG_DATA(c), sizeof(ts))
                stamp[0] = <long long>ts.tv_sec * 1_000_000_000 + ts.tv_nsec
            elif (c.cmsg_level == SOL_PACKET and c.cmsg_type == PACKET_AUXDATA
                    and c.cmsg_len >= CMSG_LEN(sizeof(tpacket_auxdata))):
                memcpy(&aux, CMSG_DATA(c), sizeof(aux))
                if aux.tp_status & TP_STATUS_VLAN_VALID and n >= 12 and n + 4 <= cap:
                    tpid = ETH_P_8021Q
                    if aux.tp_status & TP_STATUS_VLAN_TPID_VALID:
                        tpid = aux.tp_vlan_tpid
                    memmove(buf + 16, buf + 12, <size_t>(n - 12))
                    buf[12] = <uint8_t>(tpid >> 8)
                    buf[13] = <uint8_t>tpid
                    buf[14] = <uint8_t>(aux.tp_vlan_tci >> 8)
                    buf[15] = <uint8_t>aux.tp_vlan_tci
                    n += 4
            c = CMSG_NXTHDR(&msg, c)
        return n


cdef int arm(int tfd, long long deadline) noexcept nogil:
    """Arm timer fd ``tfd`` for ``deadline`` (absolute, CLOCK_MONOTONIC) unless it already
    is: the kernel's timer is programmed once per deadline, not once per wait. -1 on
    error (errno). Ref: timerfd_create(2)."""
    cdef itimerspec its
    if armed[tfd] == deadline:
        return 0
    memset(&its, 0, sizeof(its))
    its.it_value.tv_sec = <time_t>(deadline // 1_000_000_000)
    its.it_value.tv_nsec = deadline % 1_000_000_000
    if its.it_value.tv_sec == 0 and its.it_value.tv_nsec == 0:
        its.it_value.tv_nsec = 1  # all zero would disarm it
    if timerfd_settime(tfd, TFD_TIMER_ABSTIME, &its, NULL) < 0:
        return -1
    armed[tfd] = deadline
    return 0


cdef bint other_threads() noexcept:
    """Another Python thread exists: the wait releases the GIL for it. The daemon has
    none, and taking the GIL back after the wake-up costs microseconds per frame (P9). No
    thread can start while this one blocks holding the GIL."""
    cdef PyThreadState *me = PyThreadState_Get()
    cdef PyThreadState *t = PyInterpreterState_ThreadHead(PyThreadState_GetInterpreter(me))
    return t != NULL and (t != me or PyThreadState_Next(t) != NULL)


cdef int wait_fds(pollfd *pfd, nfds_t n, const timespec *ts) noexcept:
    """ppoll(2), with the GIL released only if another Python thread could use it."""
    cdef int rc
    if not other_threads():
        return ppoll(pfd, n, ts, NULL)
    with nogil:
        rc = ppoll(pfd, n, ts, NULL)
    return rc


cdef long wait_frame(int fd, pollfd *pfd, int nothers, int tfd, uint8_t *buf, long cap,
                     long long deadline, bint busy, long long *stamp) except? ERROR:
    """Wait for a frame (or the deadline, or ``others``) and receive it: its length > 0,
    or -TIMEOUT, -WAKE. ``pfd``: the link, ``others``, then the timer fd if ``tfd`` >= 0.
    With a timer fd the wait has no timeout of its own: ppoll(2) with a timeout arms and
    cancels a kernel timer on every call, which is costly in a VM (decision P9)."""
    cdef long n
    cdef long long left
    cdef int rc, i
    cdef unsigned spin = 0
    cdef uint64_t expirations
    cdef timespec ts
    while True:
        spin += 1
        n = raw_recv(fd, buf, cap, stamp)
        if n > 0:
            return n
        if n < 0:
            raise OSError(-n, strerror(-n))
        PyErr_CheckSignals()
        left = deadline - clock_ns(CLOCK_MONOTONIC)
        if left <= 0:
            return -TIMEOUT
        if busy:
            if spin % BUSY_SPINS or nothers == 0:
                continue
            rc = poll(pfd + 1, <nfds_t>nothers, 0)
        elif tfd >= 0:
            if arm(tfd, deadline) < 0:
                PyErr_SetFromErrno(OSError)
            rc = wait_fds(pfd, <nfds_t>(nothers + 2), NULL)
            if rc > 0 and pfd[nothers + 1].revents:
                if read(tfd, &expirations, sizeof(expirations)) < 0 and errno != EAGAIN:
                    PyErr_SetFromErrno(OSError)
        else:
            ts.tv_sec = <time_t>(left // 1_000_000_000)
            ts.tv_nsec = left % 1_000_000_000
            rc = wait_fds(pfd, <nfds_t>(nothers + 1), &ts)
        if rc < 0:
            if errno != EINTR:
                PyErr_SetFromErrno(OSError)
            PyErr_CheckSignals()
            return -WAKE  # a handler ran: the loop looks at its stop flag
        for i in range(1, nothers + 1):
            if pfd[i].revents:
                return -WAKE


def timer() -> int:
    """A timer fd for serve()'s deadlines (the caller closes it). Ref: timerfd_create(2)."""
    cdef int tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
    if tfd < 0:
        PyErr_SetFromErrno(OSError)
    if tfd >= MAX_TIMER_FD:
        close(tfd)
        raise OSError("timer fd number too large")
    armed[tfd] = -1
    return tfd


cdef int answer(int fd, bytearray buf, bytearray rx_copy, long n, object seg,
                long long t_rx) except -1:
    """Daemon.handle_frame and Daemon._answer for a frame served whole: keep it as
    received in ``rx_copy``, fire the SYNC pulses due before it, process it, then send the
    reply (or not: DROPPED). FRAME: not an EtherCAT frame (Python ignores it).
    Ref: ETG.1000.4 §5.3-5.4."""
    cdef uint8_t *b = <uint8_t *>(<char *>buf)
    cdef long long off = ecat_offset(buf, n, True)
    if off < 0:
        return FRAME
    memcpy(<char *>rx_copy, b, <size_t>n)
    try:
        seg.pulses_due(t_rx)  # pulses due before this frame arrived come first
        reply = seg.process(buf, off, n, t_rx)
    except Exception as exc:
        raise SegmentError(n) from exc
    if not reply:
        return DROPPED
    mark_processed(buf)
    b = <uint8_t *>(<char *>buf)
    if send(fd, b, <size_t>n, 0) < 0:
        if errno not in (ENOBUFS, EAGAIN, ENETDOWN, ENXIO):  # dropped, as a wire would
            PyErr_SetFromErrno(OSError)
    sched_yield()  # a master woken on this CPU takes the reply first (Daemon._answer)
    return REPLIED


def serve(int fd, tuple others not None, bytearray buf not None, bytearray rx_copy not None,
          long long deadline_ns, bint busy, seg, long long t_rx, int timer_fd):
    """Wait until a frame arrives, ``deadline_ns`` (host monotonic) passes or one of
    ``others`` (fds) is readable, and serve the frame with ``seg`` (a Segment; None: hand
    every frame back as FRAME). ``rx_copy`` (as large as ``buf``): the frame as received,
    for the recorder, when served here. ``busy``: spin instead of sleeping in ppoll(2).
    ``t_rx``: the frame's arrival time (host monotonic ns; 0: from the kernel's receive
    time stamp). ``timer_fd``: from timer(), or -1 (a ppoll timeout instead).

    Returns (code, n, t_rx): TIMEOUT or WAKE with n = 0, else the frame's length in buf
    and its arrival time. Raises SegmentError (from the segment's exception) where
    Segment.process would raise in Daemon.handle_frame, OSError where the socket fails."""
    cdef pollfd pfd[MAX_WATCH + 2]
    cdef Py_ssize_t nothers = len(others)
    cdef Py_ssize_t i
    cdef long long stamp = 0
    cdef long n
    if len(rx_copy) < len(buf):
        raise TypeError("rx_copy: smaller than buf")
    if nothers > MAX_WATCH:
        raise ValueError("too many fds to watch")
    if timer_fd >= MAX_TIMER_FD:
        raise ValueError("timer_fd: not from timer()")
    pfd[0].fd = fd
    pfd[0].events = POLLIN
    for i in range(nothers):
        pfd[i + 1].fd = others[i]
        pfd[i + 1].events = POLLIN
        pfd[i + 1].revents = 0
    pfd[nothers + 1].fd = timer_fd
    pfd[nothers + 1].events = POLLIN
    pfd[nothers + 1].revents = 0
    n = wait_frame(fd, pfd, <int>nothers, timer_fd, <uint8_t *>(<char *>buf), len(buf),
                   deadline_ns, busy, &stamp)
    if n <= 0:
        return (-n, 0, 0)
    if not t_rx:
        t_rx = rx_time(stamp)
    if seg is None:
        return (FRAME, n, t_rx)
    return (answer(fd, buf, rx_copy, n, seg, t_rx), n, t_rx)
