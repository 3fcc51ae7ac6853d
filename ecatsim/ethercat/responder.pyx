# cython: language_level=3
"""The daemon's compiled responder (decision P9): the raw link's steady state with no
Python bytecode run. One :class:`Responder` per link waits, receives each frame with its
kernel time stamp, records it, walks it, sends the reply, then runs the work after the
reply and the segment's timers, and goes back to waiting; it returns to the daemon only
where Python is needed (another descriptor, a signal, the daemon's own deadline, a frame
it does not serve whole). With an out link (``--out-iface``, decision L9) it waits on both
links, passes each frame in with the link it came from, and sends it where the segment
says it leaves.

What happens to a frame is written once, in the core's per-frame sequence
(ecatsim/ethercat/sequence.py, decision P21), which :meth:`Daemon.handle_frame` runs too:
``FrameSequence.arrive`` (record, the SYNC pulses due before it, the walk, the processed
bit), then the send here, then ``FrameSequence.after`` and ``FrameSequence.service``; a
timer that falls due is ``Segment.service_at``. Only the I/O is here: ppoll(2) (or
a busy spin) on the raw socket, the other descriptors and a timerfd_create(2) timer armed
once per deadline; recvmsg(2) on the packet(7) socket with its SO_TIMESTAMPNS receive time
(socket(7)) and the 802.1Q tag from PACKET_AUXDATA, as ``RawLink.recv_into`` receives
(ecatsim/link/raw.py); send(2) as ``RawLink.send``.

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

from ecatsim.ethercat.recorder cimport FrameRecorder
from ecatsim.ethercat.prefetch cimport hot_lines
from ecatsim.ethercat.segment cimport Segment
from ecatsim.ethercat.sequence cimport FrameSequence, _NOT_ECAT, _DROPPED

from os import strerror


cdef extern from *:
    """
    static inline void ecatsim_prefetch(const void *p) { __builtin_prefetch(p, 0, 3); }
    """
    void ecatsim_prefetch(const void *p) noexcept nogil

cdef extern from "Python.h":
    ctypedef struct PyTypeObject:
        Py_ssize_t tp_basicsize
    PyTypeObject *Py_TYPE(object o)
    char *PyByteArray_AS_STRING(object o)
    Py_ssize_t PyByteArray_GET_SIZE(object o)
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
    int sched_getscheduler(int pid)
    enum: SCHED_FIFO
    enum: SCHED_RR


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
    REPLIED = 3  # the frame was processed and its reply sent (the last one, with timers)
    DROPPED = 4  # the frame was processed and destroyed (Segment.process returned False)

cdef enum:
    #: the fds ``others`` may hold besides the link's
    MAX_WATCH = 8
    #: busy mode: spins between two looks at ``others``
    BUSY_SPINS = 64
    #: cache lines prefetched at each wake-up (decision P18), and the frames between two
    #: looks at what they are
    MAX_HOT = 512
    HOT_REFRESH = 1000
    #: recvmsg(2)'s control buffer in 8-byte words (PACKET_AUXDATA and SO_TIMESTAMPNS)
    CONTROL_WORDS = 32
    #: a receive time stamp older than this: the wall clock was stepped (raw.py)
    MAX_RX_AGE_NS = 1_000_000_000
    ETH_P_8021Q = 0x8100
    #: an error was raised (the Python error indicator is set)
    ERROR = -1000
    #: wait_frame: a timer (no frame) ended the wait
    NO_FRAME = 0

cdef enum:
    #: what serve() was running when an exception came, so that it names it (a try block
    #: per call would cost every frame its set-up)
    IN_NOTHING = 0
    IN_FRAME = 1  # Schedule.pulses_due, Segment.process: SegmentError
    IN_AFTER = 2  # Segment.after_reply: ServiceError("process", ...)
    IN_SERVICE = 3  # Segment.service_at: ServiceError("service", ...)


class SegmentError(Exception):
    """``Schedule.pulses_due`` or ``Segment.process`` raised on a frame (the cause): the
    frame's failure, told apart from a failure of the socket (an OSError of serve()).
    ``args[0]``: the frame's length (the recorder holds it as received)."""


class ServiceError(Exception):
    """The work after a reply or a timer raised (the cause). ``args``: where (``"process"``:
    ``Segment.after_reply``, ``"service"``: ``Segment.service``), the time it ran for
    (host monotonic ns) and serve()'s code for what came before (REPLIED or DROPPED: a
    frame, TIMEOUT: a timer); the daemon counts it and runs what was left, as
    :meth:`Daemon._after` does."""


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




cdef class Responder:
    """The raw link's steady state (decision P9). ``fd``: the link's socket; ``out_fd``: the
    out link's (-1: none), frames from it enter the segment at its out port and frames the
    segment sends on leave on it; ``others``: descriptors that end a wait (wake-up pipe,
    control socket, front doors);
    ``recorder``: where each frame served here is kept as received; ``busy``: spin
    instead of sleeping in ppoll(2); ``timer``: wait on a timerfd(2) armed once per
    deadline, not a ppoll timeout (which arms and cancels a kernel timer on every call,
    costly in a VM). :meth:`set_follow`: the daemon's CPU following (decision K5), or
    none. ``replied``: frames sent so far; ``entry``: the link the last frame came from
    (0: the daemon's, 1: the out link)."""

    cdef int fd, out_fd, tfd, nothers
    cdef readonly int entry
    #: the link, ``others``, the timer fd, the CPU follower's fd, the out link
    cdef pollfd pfd[MAX_WATCH + 4]
    #: the deadline the timer fd is armed for (-1: none)
    cdef long long armed
    cdef bytearray buf
    cdef FrameRecorder recorder
    cdef readonly bint busy
    #: the CPU following: called with a time after a frame from another CPU, returns the
    #: next time to call it without one (0: none)
    cdef object follow
    cdef long long follow_at
    cdef bint follow_due
    cdef readonly long long replied
    #: the daemon's own reply times (decision B9), for frames whose arrival time is the
    #: kernel's receive time stamp: from it to after send(2) the longest and how many took
    #: 1 ms or more and 2 ms or more; from it to the start of the frame's processing (the
    #: frame waited in the socket) the longest, and how many of the replies of 2 ms or
    #: more waited 1 ms or more before it
    cdef readonly long long reply_max_ns, replies_over_1ms, replies_over_2ms
    cdef readonly long long pickup_max_ns, late_picked_up_late
    cdef bint timed
    #: the process runs SCHED_FIFO/RR: a yield after the reply gives nothing to a master
    cdef bint rt
    #: the segment call running (IN_*), and the frame's length, time and serve() code
    cdef int stage, stage_code
    cdef long stage_n
    cdef long long stage_t
    #: the cache lines a cyclic frame reads (prefetch.hot_lines), prefetched as the wait
    #: ends, before the receive (decision P18); the objects are held here
    cdef const char *hot[MAX_HOT]
    cdef int nhot
    cdef tuple hot_refs
    cdef long long hot_next

    def __cinit__(self) -> None:
        self.tfd = -1

    def __init__(self, int fd, tuple others not None, FrameRecorder recorder not None,
                 bint busy=False, bint timer=True, int out_fd=-1) -> None:
        cdef Py_ssize_t i
        if len(others) > MAX_WATCH:
            raise ValueError("too many fds to watch")
        self.fd = fd
        self.out_fd = out_fd
        self.entry = 0
        self.nothers = <int>len(others)
        self.recorder = recorder
        self.busy = busy
        self.follow = None
        self.follow_at = 0
        self.armed = -1
        self.pfd[0].fd = fd
        self.pfd[0].events = POLLIN
        for i in range(self.nothers):
            self.pfd[i + 1].fd = others[i]
            self.pfd[i + 1].events = POLLIN
        if timer:
            self.tfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
            if self.tfd < 0:
                PyErr_SetFromErrno(OSError)
        self.pfd[self.nothers + 1].fd = self.tfd
        self.pfd[self.nothers + 1].events = POLLIN
        self.pfd[self.nothers + 2].fd = -1
        self.pfd[self.nothers + 2].events = POLLIN
        self.pfd[self.nothers + 3].fd = out_fd
        self.pfd[self.nothers + 3].events = POLLIN

    def __dealloc__(self) -> None:
        if self.tfd >= 0:
            close(self.tfd)

    def set_follow(self, follow, int fd, long long look_ns) -> None:
        """The CPU following (decision K5): ``fd`` is readable when frames have come in on
        another CPU; after the frame that came with it (or at once, if none did) the
        responder calls ``follow(t)``, which returns when to call it again with nothing
        readable (0: never), as it does also after a frame arriving at ``look_ns`` or
        later. ``follow`` None: no following."""
        self.follow = follow
        self.pfd[self.nothers + 2].fd = fd if follow is not None else -1
        self.follow_at = look_ns
        if follow is None:
            self.follow_due = False

    cdef int look_hot(self, Segment seg) except -1:
        """Take the lines to prefetch from ``hot_lines(seg)`` (ecatsim/ethercat/prefetch.py):
        each object's whole struct and each (bytearray, start, stop) range."""
        cdef tuple hot = hot_lines(seg)
        cdef Py_ssize_t a, b
        self.nhot = 0
        for it in hot[0]:
            self.add_hot(<const char *><void *>it, 0, Py_TYPE(it).tp_basicsize)
        for ba, a, b in hot[1]:
            self.add_hot(PyByteArray_AS_STRING(ba), max(0, a), min(PyByteArray_GET_SIZE(ba), b))
        self.hot_refs = hot
        self.hot_next = self.replied + HOT_REFRESH
        return 0

    cdef void add_hot(self, const char *p, Py_ssize_t a, Py_ssize_t b) noexcept:
        """The cache lines of [p + a, p + b), while there is room."""
        while a < b and self.nhot < MAX_HOT:
            self.hot[self.nhot] = p + a
            self.nhot += 1
            a += 64

    cdef void prefetch(self) noexcept:
        cdef int i
        for i in range(self.nhot):
            ecatsim_prefetch(self.hot[i])

    cdef int run_follow(self, long long t) except -1:
        self.follow_due = False
        self.follow_at = self.follow(t)
        return 0

    def frame_waiting(self) -> bool:
        """A frame waits on the link or the out link (poll(2) without waiting): the
        segment's work after a reply stops for it (``Schedule.frame_waiting``, decisions P19
        and L9)."""
        cdef pollfd p[2]
        p[0].fd = self.fd
        p[0].events = POLLIN
        p[0].revents = 0
        p[1].fd = self.out_fd
        p[1].events = POLLIN
        p[1].revents = 0
        return poll(p, 2, 0) > 0  # an out_fd of -1 is ignored (poll(2))

    def close(self) -> None:
        """Close the timer fd (the link's socket is the caller's)."""
        if self.tfd >= 0:
            close(self.tfd)
            self.tfd = -1
            self.pfd[self.nothers + 1].fd = -1

    cdef int arm(self, long long deadline) except -1:
        """Arm the timer fd for ``deadline`` (absolute, CLOCK_MONOTONIC) unless it already
        is: the kernel's timer is programmed once per deadline, not once per wait.
        Ref: timerfd_create(2)."""
        cdef itimerspec its
        if self.armed == deadline:
            return 0
        memset(&its, 0, sizeof(its))
        its.it_value.tv_sec = <time_t>(deadline // 1_000_000_000)
        its.it_value.tv_nsec = deadline % 1_000_000_000
        if its.it_value.tv_sec == 0 and its.it_value.tv_nsec == 0:
            its.it_value.tv_nsec = 1  # all zero would disarm it
        if timerfd_settime(self.tfd, TFD_TIMER_ABSTIME, &its, NULL) < 0:
            PyErr_SetFromErrno(OSError)
        self.armed = deadline
        return 0

    cdef long receive(self, bint link, bint out, long long *stamp) except? ERROR:
        """A frame from the link (if ``link``) or else the out link (if ``out``): its length
        (``entry`` says which link), 0 if none is waiting."""
        cdef long n = 0
        cdef uint8_t *buf = <uint8_t *>(<char *>self.buf)
        if link:
            n = raw_recv(self.fd, buf, len(self.buf), stamp)
            self.entry = 0
        if n == 0 and out and self.out_fd >= 0:
            n = raw_recv(self.out_fd, buf, len(self.buf), stamp)
            self.entry = 1
        if n < 0:
            raise OSError(-n, strerror(-n))
        return n

    cdef long wait_frame(self, long long deadline, long long *stamp) except? ERROR:
        """Wait for a frame (or the deadline, or ``others``) and receive it: its length
        > 0, or NO_FRAME (the deadline), -WAKE. Without busy spinning, a link is read
        only where ppoll(2) says it is readable (a receive that finds nothing is a
        system call for nothing), or once where the deadline has already passed."""
        cdef long n
        cdef long long left
        cdef int rc, i
        cdef int nothers = self.nothers
        cdef unsigned spin = 0
        cdef uint64_t expirations
        cdef timespec ts
        cdef pollfd *pfd = self.pfd
        # a frame waiting is served before a deadline that has passed
        cdef bint look = self.busy or deadline <= clock_ns(CLOCK_MONOTONIC)
        cdef bint look_out = look
        while True:
            if look or look_out:
                n = self.receive(look, look_out, stamp)
                if n > 0:
                    return n
            PyErr_CheckSignals()
            left = deadline - clock_ns(CLOCK_MONOTONIC)
            if left <= 0:
                return NO_FRAME
            if self.busy:
                spin += 1
                if spin % BUSY_SPINS or nothers == 0:
                    continue
                rc = poll(pfd + 1, <nfds_t>(nothers + 2), 0)
            elif self.tfd >= 0:
                self.arm(deadline)
                rc = wait_fds(pfd, <nfds_t>(nothers + 4), NULL)
                if rc > 0 and pfd[nothers + 1].revents:
                    if read(self.tfd, &expirations, sizeof(expirations)) < 0 and errno != EAGAIN:
                        PyErr_SetFromErrno(OSError)
            else:
                ts.tv_sec = <time_t>(left // 1_000_000_000)
                ts.tv_nsec = left % 1_000_000_000
                rc = wait_fds(pfd, <nfds_t>(nothers + 4), &ts)  # no timer fd: -1, ignored
            if rc < 0:
                if errno != EINTR:
                    PyErr_SetFromErrno(OSError)
                PyErr_CheckSignals()
                return -WAKE  # a handler ran: the loop looks at its stop flag
            for i in range(1, nothers + 1):
                if pfd[i].revents:
                    return -WAKE
            look = self.busy or (rc > 0 and pfd[0].revents != 0)
            look_out = self.busy or (rc > 0 and pfd[nothers + 3].revents != 0)
            if (look or look_out) and not self.busy:
                self.prefetch()  # while the receive runs, the walk's lines come in
            if rc > 0 and pfd[nothers + 2].revents:
                self.follow_due = True  # after this frame, or now if none came with it
                if not (look or look_out):
                    self.run_follow(clock_ns(CLOCK_MONOTONIC))

    cdef int answer(self, long n, FrameSequence seq, long long t_rx) except -1:
        """The per-frame sequence's first step (``FrameSequence.arrive``), then the send:
        REPLIED, DROPPED (destroyed: no reply) or FRAME (not an EtherCAT frame: Python
        ignores it). Ref: ETG.1000.4 §5.3-5.4."""
        cdef long long code
        cdef long long picked = clock_ns(CLOCK_MONOTONIC) if self.timed else 0
        cdef int fd
        self.stage = IN_FRAME
        self.stage_n = n
        code = seq.arrive(self.buf, n, t_rx, self.entry)
        self.stage = IN_NOTHING
        if code == _NOT_ECAT:
            return FRAME
        if code == _DROPPED:
            return DROPPED
        fd = self.out_fd if self.out_fd >= 0 and seq.segment.exit else self.fd  # it leaves there
        if send(fd, <uint8_t *>(<char *>self.buf), <size_t>n, 0) < 0:
            if errno not in (ENOBUFS, EAGAIN, ENETDOWN, ENXIO):  # dropped, as a wire would
                PyErr_SetFromErrno(OSError)
        self.replied += 1
        if self.timed:
            self.time_reply(t_rx, picked)
        if not self.rt:
            sched_yield()  # a master woken on this CPU takes the reply first (Daemon._answer)
        return REPLIED

    cdef void time_reply(self, long long t_rx, long long picked) noexcept:
        """Count a reply sent now to a frame received at ``t_rx`` and picked up at
        ``picked`` (host monotonic ns; decision B9)."""
        cdef long long took = clock_ns(CLOCK_MONOTONIC) - t_rx
        cdef long long waited = picked - t_rx
        if took > self.reply_max_ns:
            self.reply_max_ns = took
        if waited > self.pickup_max_ns:
            self.pickup_max_ns = waited
        if took >= 1_000_000:
            self.replies_over_1ms += 1
            if took >= 2_000_000:
                self.replies_over_2ms += 1
                if waited >= 1_000_000:
                    self.late_picked_up_late += 1

    def reply_times(self) -> dict:
        """The daemon's own reply times (decision B9) for its ``stopped`` line."""
        return {
            "reply_max_us": self.reply_max_ns // 1000,
            "replies_over_1ms": self.replies_over_1ms,
            "replies_over_2ms": self.replies_over_2ms,
            "pickup_max_us": self.pickup_max_ns // 1000,
            "late_picked_up_late": self.late_picked_up_late,
        }

    cdef int after(self, FrameSequence seq, long long t, int code) except -1:
        """The sequence's steps after the send: the work the frame left for after its reply
        and the firmware and timers due by its arrival; then the CPU following."""
        self.stage = IN_AFTER
        self.stage_t = t
        self.stage_code = code
        seq.after()
        self.stage = IN_SERVICE
        seq.service(t)
        self.stage = IN_NOTHING
        if self.follow is not None and (self.follow_due or 0 < self.follow_at <= t):
            self.run_follow(t)
        return 0

    def serve(self, bytearray buf not None, long long deadline_ns, FrameSequence seq=None,
              long long t_rx=0, bint timers=False):
        """Wait until a frame arrives in ``buf``, ``deadline_ns`` (host monotonic) passes or
        one of ``others`` is readable, and serve the frame with ``seq`` (the segment's
        per-frame sequence; None: hand every frame back as FRAME) and the work after it.
        ``t_rx``: the frame's arrival time (host monotonic ns; 0: from the kernel's receive
        time stamp).

        ``timers`` (the segment runs on the OS monotonic clock): go on serving frames, and
        run the segment's timers (``Schedule.next_deadline``, ``Segment.service``) as they
        fall due, until ``deadline_ns`` or a wake-up; without, return after one frame.

        Returns (code, n, t_rx): TIMEOUT or WAKE with n = 0, else the last frame's length
        in buf and its arrival time. Raises SegmentError (from the segment's exception)
        where Segment.process would raise in Daemon.handle_frame, ServiceError where the
        work after it would, OSError where the socket fails."""
        cdef int policy = sched_getscheduler(0)
        self.rt = policy == SCHED_FIFO or policy == SCHED_RR
        if seq is None and timers:
            raise ValueError("timers: a segment is needed")
        self.buf = buf
        self.stage = IN_NOTHING
        try:
            return self.serve_frames(deadline_ns, seq, t_rx, timers)
        except Exception as exc:
            if self.stage == IN_FRAME:
                raise SegmentError(self.stage_n) from exc
            if self.stage == IN_AFTER:
                raise ServiceError("process", self.stage_t, self.stage_code) from exc
            if self.stage == IN_SERVICE:
                raise ServiceError("service", self.stage_t, self.stage_code) from exc
            raise
        finally:
            if seq is not None:
                seq.release()  # the caller's buffer is free to change size again
            self.stage = IN_NOTHING

    cdef int service(self, Segment seg, long long t, int code) except -1:
        """``Segment.service_at(t)``, its failure a ServiceError (``code``: what serve()
        was doing, REPLIED or DROPPED after a frame, TIMEOUT for a timer)."""
        self.stage = IN_SERVICE
        self.stage_t = t
        self.stage_code = code
        seg.service_at(t)
        self.stage = IN_NOTHING
        return 0

    cdef tuple serve_frames(self, long long deadline_ns, FrameSequence seq, long long t_rx,
                            bint timers):
        """serve()'s loop."""
        cdef long long stamp = 0
        cdef long long wait_until, now, t
        cdef long n
        cdef int code, i
        cdef Segment seg = seq.segment if seq is not None else None
        self.timed = t_rx == 0  # the kernel's time stamps: the host's monotonic clock
        for i in range(self.nothers + 4):
            self.pfd[i].revents = 0
        while True:
            if seg is not None and self.replied >= self.hot_next:
                self.look_hot(seg)
            wait_until = deadline_ns
            if timers:
                wait_until = min(wait_until, seg.schedule.next_deadline_ns())  # NO_DEADLINE: none
            n = self.wait_frame(wait_until, &stamp)
            if n == -WAKE:
                return (WAKE, 0, 0)
            if n == NO_FRAME:
                now = clock_ns(CLOCK_MONOTONIC)
                if not timers or now >= deadline_ns:
                    return (TIMEOUT, 0, 0)
                self.service(seg, now, TIMEOUT)  # a SYNC pulse or a watchdog of the segment
                continue
            t = t_rx if t_rx else rx_time(stamp)
            if seq is None:
                return (FRAME, n, t)
            code = self.answer(n, seq, t)
            if code == FRAME:
                return (FRAME, n, t)
            self.after(seq, t, code)
            if not timers:
                return (code, n, t)
