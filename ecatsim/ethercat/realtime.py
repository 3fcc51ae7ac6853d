"""Real-time scheduling and locked memory for the daemon, where the host allows them.

A stock master times out after 2 ms or less (KickCAT's default link timeout is 2 ms): on a
busy machine the daemon must be woken before the ordinary tasks that keep both CPUs busy.
The blocking daemon therefore takes ``SCHED_FIFO`` at a modest priority by default (below
the kernel's threaded interrupts at 50 and below a real-time master), and locks the memory
it has built so a reply never waits for a page to come back. ``--rt-priority N`` picks the
priority; ``--no-rt`` keeps the ordinary scheduler. See docs/decisions.md K1.

A real-time daemon also asks the kernel to keep every CPU out of its idle states (a CPU
latency request of 0 us on ``/dev/cpu_dma_latency``, held while the daemon runs, as
cyclictest does): a frame arriving on another CPU wakes the daemon through an interrupt to
its CPU, and a CPU that has to come out of an idle state first (on a virtual machine, a
virtual CPU the host has descheduled) answers late. ``--no-hold-cpu-latency`` leaves the
idle states alone. See docs/decisions.md K12.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import os
import struct

import structlog

from ecatsim.errors import UserError

log = structlog.get_logger("ecatsim.ethercat.realtime")

#: the SCHED_FIFO priority the blocking daemon takes unless told otherwise
DEFAULT_PRIORITY = 20

#: mlockall(2) flags (linux/mman.h)
MCL_CURRENT = 1

#: the PM QoS CPU latency request: a 32-bit value in us, in force while the file is open.
#: Ref: the kernel's Documentation/power/pm_qos_interface.rst
CPU_LATENCY_PATH = "/dev/cpu_dma_latency"


def choose_priority(
    rt_priority: int | None, no_rt: bool, busy_poll: bool, cpu: int | None
) -> int | None:
    """The SCHED_FIFO priority to ask for, or None for the ordinary scheduler.

    Busy-poll spins: as a real-time task it would starve every other task on its CPU, so
    it is real-time only when asked, and then only pinned to one CPU."""
    if no_rt:
        if rt_priority is not None:
            raise UserError("--no-rt and --rt-priority exclude each other")
        return None
    if rt_priority is not None:
        if busy_poll and cpu is None:
            raise UserError(
                "--rt-priority with --busy-poll needs --cpu N: a spinning real-time "
                "task would starve every other task on its CPU"
            )
        return rt_priority
    return None if busy_poll else DEFAULT_PRIORITY


def set_fifo(priority: int, explicit: bool) -> bool:
    """Take SCHED_FIFO at ``priority``. Without the capability: an error if the user asked
    for it (``explicit``), else one warning line and the ordinary scheduler."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        if explicit:
            raise UserError(
                f"--rt-priority {priority}: cannot set SCHED_FIFO ({exc.strerror}); "
                "run as root or with CAP_SYS_NICE"
            ) from exc
        log.warning(
            "realtime_unavailable",
            reason=exc.strerror,
            hint="run as root or with CAP_SYS_NICE for SCHED_FIFO; --no-rt silences this",
        )
        return False
    log.info("realtime", policy="SCHED_FIFO", priority=priority, off_switch="--no-rt")
    return True


def lock_memory() -> bool:
    """Lock the pages the daemon has now (``mlockall(MCL_CURRENT)``). Pages allocated later
    are not locked: with MCL_FUTURE, a daemon that drops root (``--user``) would see its
    allocations fail once RLIMIT_MEMLOCK is reached."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    if libc.mlockall(MCL_CURRENT) == 0:
        log.info("memory_locked")
        return True
    err = ctypes.get_errno()
    log.warning("memory_not_locked", reason=os.strerror(err), errno=errno.errorcode.get(err, err))
    return False


def apply(priority: int | None, explicit: bool) -> bool:
    """Scheduling class and memory lock for the serving loop (call once everything is
    built). True if the daemon now runs SCHED_FIFO."""
    if priority is None:
        return False
    if not set_fifo(priority, explicit):
        return False
    lock_memory()
    return True


def hold_cpu_latency(path: str = CPU_LATENCY_PATH) -> int | None:
    """Ask for a CPU wake-up latency of 0 us (no CPU enters an idle state it would be slow
    to leave) for as long as the returned file descriptor stays open; close it to give the
    request back (the kernel does so when the process ends). Without the file or the
    permission: one warning line and None."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC)
    except OSError as exc:
        log.warning(
            "cpu_latency_not_held",
            path=path,
            reason=exc.strerror,
            hint="wake-ups may wait for CPUs to leave their idle states; "
            "--no-hold-cpu-latency silences this",
        )
        return None
    try:
        os.write(fd, struct.pack("=i", 0))
    except OSError as exc:
        os.close(fd)
        log.warning("cpu_latency_not_held", path=path, reason=exc.strerror)
        return None
    log.info("cpu_latency_held", us=0, path=path, off_switch="--no-hold-cpu-latency")
    return fd
