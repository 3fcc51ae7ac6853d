"""SyncManager: mailbox (single buffer) and buffered (3-buffer) mode, both faces.

The SM controls a window of ESC memory. In mailbox mode the window is one buffer that
alternates between full and empty; in buffered mode the window is backed by three
buffers at ``start``, ``start + len`` and ``start + 2 * len`` and accesses are
redirected, so the reader always sees the latest complete buffer.

Ref: TMC8460 §5.49 Tables 85-91; ETG.1000.4 §6.7 (SyncManager).
"""

from __future__ import annotations

from ecatsim.esc import regs
from ecatsim.esc.regs import (
    DC_ECAT_EVENT_TIME,
    SM_ACT_LATCH_ECAT,
    SM_CTRL_ECAT_IRQ,
    SM_CTRL_PDI_IRQ,
    SM_CTRL_WATCHDOG,
    SM_DIR_MASK,
    SM_DIR_WRITE,
    SM_MODE_MAILBOX,
    SM_MODE_MASK,
    SM_ST_BUF_SHIFT,
    SM_ST_IRQ_READ,
    SM_ST_IRQ_WRITE,
    SM_ST_MBX_FULL,
    SM_ST_READ_OPEN,
    SM_ST_WRITE_OPEN,
)


def _copy(dst: bytearray, d: int, src: bytearray, s: int, n: int) -> None:
    """``dst[d:d + n] = src[s:s + n]`` for ranges the caller checked (compiled: C pointers,
    four bytes a step: a byte loop costs its count and test per byte, decision P62)."""
    k = 0
    while k + 4 <= n:
        dst[d + k] = src[s + k]
        dst[d + k + 1] = src[s + k + 1]
        dst[d + k + 2] = src[s + k + 2]
        dst[d + k + 3] = src[s + k + 3]
        k += 4
    while k < n:
        dst[d + k] = src[s + k]
        k += 1


class SmHost:
    """What an SM needs from its ESC: memory and event lines. The ESC derives from this
    class (compiled: the SM calls these through the C method table, sm.pxd)."""

    __slots__ = ()

    def memory(self) -> bytearray:
        """The ESC memory the SM's windows and buffers live in."""
        raise NotImplementedError

    def sm_status_changed(self, sm: SyncManager) -> None:
        """The SM's event bits (``sm.mirror``) changed: update the event registers."""
        raise NotImplementedError

    def wd_pd_trigger(self) -> None:
        """A write of the SM's buffer triggers the process-data watchdog."""
        raise NotImplementedError

    def sm_event_time(self, reg: int) -> None:
        """Take the SyncManager event time ``reg`` (0x09F0, 0x09F8 or 0x09FC) now."""
        raise NotImplementedError

    def sm_restart(self, n: int) -> None:
        """Restart SM ``n`` with its registers' values and compile the ESC's windows."""
        raise NotImplementedError


class SyncManager:
    """One SyncManager channel (state machine and redirection)."""

    __slots__ = (
        "active",
        "changed",
        "control",
        "ecat_side_writes",
        "enabled",
        "host",
        "irq_to_ecat",
        "irq_to_pdi",
        "l",
        "length",
        "locked",
        "mailbox",
        "mbx_full",
        "mem",
        "mirror",
        "mp",
        "mv",
        "n",
        "r",
        "r_open",
        "start",
        "status",
        "status_addr",
        "w",
        "w_open",
    )

    def __init__(self, host: SmHost, n: int) -> None:
        self.host = host
        #: the ESC memory the windows and buffers live in (the host's, for its lifetime)
        self.mem = host.memory()
        self.mv = memoryview(self.mem)
        #: compiled: a pointer to the memory's bytes (fixed: the view holds the buffer)
        self.mp = self.mem
        self.n = n
        self.status_addr = regs.sm_addr(n, 5)
        if len(self.mem) < self.status_addr + 2:  # the status and activate registers
            raise IndexError(self.status_addr)
        self.start = 0
        self.length = 0
        self.control = 0
        self.active = False
        self.enabled = False
        self.locked = False
        self.mailbox = False
        self.ecat_side_writes = False
        self.mbx_full = False
        # buffered mode roles: w = being written, l = latest complete (-1 none), r = being read
        self.w = 0
        self.l = -1
        self.r = 0
        self.r_open = False
        self.w_open = False
        self.status = 0
        #: the event bits last mirrored into 0x0210/0x0220 (-1: mirror on the next change):
        #: bit 0 ECAT event, bit 1 AL event (PDI)
        self.mirror = -1
        #: the bits of ``mirror`` its last change changed (all after a restart, decision P29)
        self.changed = 3
        #: the status bit (0x0805+8n) that raises the ECAT / the AL event, 0 if disabled
        self.irq_to_ecat = 0
        self.irq_to_pdi = 0

    # -- configuration -------------------------------------------------------------

    def configure(
        self, start: int, length: int, control: int, active: bool, locked: bool = False
    ) -> None:
        """(Re)start the SM with its register values; resets the buffer state.

        ``active`` is the ECAT enable (0x0806.0); ``locked`` the PDI deactivate bit
        (0x0807.0), which resets the SM and locks its memory area for both sides.
        Ref: TMC8460 §5.49 Table 90 (activation resets the SM), Table 91 (PDI deactivate).
        """
        self.locked = locked
        self.enabled = active
        self.start = start
        self.length = length
        self.control = control
        self.mailbox = (control & SM_MODE_MASK) == SM_MODE_MAILBOX
        self.ecat_side_writes = (control & SM_DIR_MASK) == SM_DIR_WRITE
        # a length of 1 does not activate the SM (only its watchdog trigger: Esc)
        self.active = active and length > 1
        self.mbx_full = False
        self.w = 0
        self.l = -1
        self.r = 0
        self.r_open = False
        self.w_open = False
        self.status = 0
        self.mirror = -1
        # The write interrupt goes to the reading side, the read interrupt to the writing
        # side, each if enabled in the control register. Ref: §5.49 Tables 88, 89.
        to_ecat = SM_ST_IRQ_READ if self.ecat_side_writes else SM_ST_IRQ_WRITE
        to_pdi = SM_ST_IRQ_WRITE if self.ecat_side_writes else SM_ST_IRQ_READ
        self.irq_to_ecat = to_ecat if control & SM_CTRL_ECAT_IRQ else 0
        self.irq_to_pdi = to_pdi if control & SM_CTRL_PDI_IRQ else 0
        self._sync()

    def window(self) -> tuple[int, int] | None:
        """The ECAT-visible window [start, end) while active."""
        if not self.active:
            return None
        return self.start, self.start + self.length

    # -- shared helpers --------------------------------------------------------------

    def _sync(self) -> None:
        st = self.status & (SM_ST_IRQ_WRITE | SM_ST_IRQ_READ)
        if self.mailbox:
            if self.mbx_full:
                st |= SM_ST_MBX_FULL
        else:
            st |= (self.l if self.l >= 0 else 3) << SM_ST_BUF_SHIFT
            if self.r_open:
                st |= SM_ST_READ_OPEN
            if self.w_open:
                st |= SM_ST_WRITE_OPEN
        self.status = st
        p = self.mp  # compiled: a C pointer (status_addr checked in __init__)
        p[self.status_addr] = st
        mirror = (1 if st & self.irq_to_ecat else 0) | (2 if st & self.irq_to_pdi else 0)
        if mirror != self.mirror:  # the event registers change only when these bits do
            self.changed = 3 if self.mirror < 0 else mirror ^ self.mirror
            self.mirror = mirror
            self.host.sm_status_changed(self)

    def _writer_access(self, first: bool, last: bool) -> None:
        if self.mailbox:
            if first:
                self.status &= ~SM_ST_IRQ_READ
            if last:
                self.mbx_full = True
                self.status |= SM_ST_IRQ_WRITE
        else:
            if first:
                self.w_open = True
                self.status &= ~SM_ST_IRQ_READ
            if last:
                self.w_open = False
                latest = self.l = self.w
                # the lowest buffer neither latest nor being read
                if self.r_open and self.r != latest:
                    self.w = 3 - latest - self.r
                else:
                    self.w = 1 if latest == 0 else 0
                self.status |= SM_ST_IRQ_WRITE
        if first or last:
            self._sync()

    def _reader_open(self) -> None:
        if not self.mailbox:
            if self.l >= 0:
                self.r = self.l
            elif self.r == self.w:
                self.r = (self.w + 1) % 3
            self.r_open = True

    def _reader_access(self, first: bool, last: bool) -> None:
        if self.mailbox:
            if first:
                self.status &= ~SM_ST_IRQ_WRITE
            if last:
                self.mbx_full = False
                self.status |= SM_ST_IRQ_READ
        else:
            if first:
                self.status &= ~SM_ST_IRQ_WRITE
            if last:
                self.r_open = False
                self.status |= SM_ST_IRQ_READ
        if first or last:
            self._sync()

    def _base_for_write(self) -> int:
        return self.start if self.mailbox else self.start + self.w * self.length

    def _base_for_read(self) -> int:
        if self.mailbox:
            return self.start
        b = self.r if self.r_open else (self.l if self.l >= 0 else self.r)
        return self.start + b * self.length

    # -- writer/reader side, face-independent -----------------------------------------

    def writer_may(self) -> bool:
        """A writer access is possible (mailbox: only while empty)."""
        return self.active and not self.locked and not (self.mailbox and self.mbx_full)

    def reader_may(self) -> bool:
        """A reader access is possible (mailbox: only while full)."""
        return self.active and not self.locked and (not self.mailbox or self.mbx_full)

    def writer_write(self, off: int, data: bytes | memoryview) -> None:
        """Write ``data`` at window offset ``off`` as the writing side.

        Ref: TMC8460 §5.49 Table 89 (buffer exchange when the last byte is written).
        """
        first = off == 0
        n = len(data)
        last = off + n >= self.length
        base = self._base_for_write() + off
        if base < 0 or base + n > len(self.mem):
            mv = self.mv  # the checked loop: wraps or raises where the memory does
            for k in range(n):
                mv[base + k] = data[k]
        else:  # compiled: a C loop through a pointer (a slice copy is a generic call), P28
            p = self.mem
            for k in range(n):
                p[base + k] = data[k]
        self._writer_access(first, last)

    def reader_read(self, off: int, out: memoryview) -> None:
        """Read into ``out`` from window offset ``off`` as the reading side."""
        first = off == 0
        n = len(out)
        last = off + n >= self.length
        if first:
            self._reader_open()
        base = self._base_for_read() + off
        if base < 0 or base + n > len(self.mem):
            mv = self.mv  # the checked loop, as in writer_write
            for k in range(n):
                out[k] = mv[base + k]
        else:  # compiled: a C loop through a pointer, as in writer_write
            p = self.mem
            for k in range(n):
                out[k] = p[base + k]
        self._reader_access(first, last)

    def read_whole(self) -> bytes:
        """The whole buffer read as the reading side (``reader_read`` of every byte).
        Compiled, the bytes object is made once from the memory's bytes (decision P28) and
        taken as it is (decision P47)."""
        self._reader_open()
        base = self._base_for_read()
        mem = self.mem
        end = min(base + self.length, len(mem))  # a slice stops at the memory's end
        p = mem  # compiled: a C pointer to the bytes (a slice of it is a bytes object)
        # joined alone: bytes in Python; compiled, the slice itself, returned by the join
        # without a copy (bytes(bytes) is a call, b"" + bytes takes two buffer views)
        data = b"".join((p[base:end],)) if base < end else b""
        self._reader_access(True, True)
        return data

    def write_whole(self, data: bytes) -> None:
        """The whole buffer written as the writing side (``writer_write`` of exactly
        ``length`` bytes). Compiled: a C loop over the bytes, the indexes checked once
        (the same IndexError after the same bytes, decision P28)."""
        base = self._base_for_write()
        mem = self.mem
        n = self.length
        if n > len(data) or base + n > len(mem):
            for i in range(n):  # the checked loop: raises where the buffers end
                mem[base + i] = data[i]
        p = mem  # compiled: C pointers, the indexes checked above
        d = data
        for i in range(n):
            p[base + i] = d[i]
        self._writer_access(True, True)

    def read_into(self, out: bytearray) -> None:
        """``read_whole`` into ``out``, made the same bytes (its length the bytes read):
        the reader's whole buffer copied through pointers into a buffer its caller keeps,
        no bytes object made (decision P70)."""
        self._reader_open()
        base = self._base_for_read()
        mem = self.mem
        k = min(base + self.length, len(mem)) - base  # a slice stops at the memory's end
        if k < 0:
            k = 0
        if len(out) != k:
            out[:] = bytes(k)  # a new length: the buffer resized (not per cycle)
        q = out  # compiled: C pointers, the ranges checked above
        _copy(q, 0, self.mp, base, k)
        self._reader_access(True, True)

    def whole_base(self, n: int) -> int:
        """Where the writing side's whole buffer starts in the memory, for a writer that
        fills its ``n`` bytes in place and then calls ``written``; -1 where it cannot and
        ``write_whole`` must: ``n`` not the SM's length, or the buffer not inside the
        memory (decision P71)."""
        base = self._base_for_write()
        if n != self.length or base < 0 or base + n > len(self.mem):
            return -1
        return base

    def written(self) -> None:
        """The writing side filled its whole buffer in place (``whole_base``): the buffer
        exchange and events of ``write_whole``."""
        self._writer_access(True, True)

    def wd_tap(self) -> bool:
        """An enabled write SM of length 1 with the watchdog trigger bit: a write of its
        byte (plain memory) triggers the process-data watchdog. Ref: TMC8460 §5.49
        Table 87 ("if set to 1, only Watchdog Trigger is generated if configured")."""
        return (
            self.enabled
            and not self.locked
            and self.ecat_side_writes
            and bool(self.control & SM_CTRL_WATCHDOG)
        )

    def peek(self, off: int, n: int) -> bytes:
        """The bytes a reader would see, without side effects (for logging and bit FMMUs)."""
        base = self._base_for_read()
        return bytes(self.mem[base + off : base + off + n])

    # -- ECAT face -------------------------------------------------------------------

    def ecat_may_write(self) -> bool:
        """Whether an ECAT write into the window is accepted (counts in the WKC)."""
        return self.ecat_side_writes and self.writer_may()

    def ecat_may_read(self) -> bool:
        """Whether an ECAT read of the window is accepted (counts in the WKC)."""
        if self.ecat_side_writes:
            return self.active and not self.locked and not self.mailbox
        return self.reader_may()

    def ecat_write(self, off: int, data: bytes | memoryview) -> None:
        """ECAT write (caller checked ecat_may_write). Its last byte exchanges the buffer:
        with 0x0806+8n bit 6 the frame's time goes to 0x09F0. Ref: §5.49 Table 90,
        §5.50.6 Table 122."""
        self.writer_write(off, data)
        if self.control & SM_CTRL_WATCHDOG:
            self.host.wd_pd_trigger()
        if off + len(data) >= self.length and self.mem[self.status_addr + 1] & SM_ACT_LATCH_ECAT:
            self.host.sm_event_time(DC_ECAT_EVENT_TIME)

    def ecat_read(self, off: int, out: memoryview) -> None:
        """ECAT read (caller checked ecat_may_read); the reader's last byte exchanges the
        buffer (event time as ecat_write)."""
        if self.ecat_side_writes:
            base = self._base_for_read()  # peek(): no side effects
            out[:] = self.mv[base + off : base + off + len(out)]
            return
        self.reader_read(off, out)
        if off + len(out) >= self.length and self.mem[self.status_addr + 1] & SM_ACT_LATCH_ECAT:
            self.host.sm_event_time(DC_ECAT_EVENT_TIME)

    def ecat_write_at(self, off: int, buf: bytearray, pos: int, n: int) -> bool:
        """``ecat_may_write()``, then ``ecat_write(off, buf[pos:pos + n])``, in one call and
        without a view of the data: the frame walk's logical path (decision P61). Returns
        whether the write counts. A range the pointers cannot take (past the memory, the
        window or the frame) goes the checked way, ``ecat_write``, with its errors."""
        if not self.ecat_side_writes or not self.active or self.locked:
            return False
        if self.mailbox and self.mbx_full:
            return False
        base = self._base_for_write() + off
        if off < 0 or pos < 0 or pos + n > len(buf) or base < 0 or base + n > len(self.mem):
            self._ecat_checked(off, buf, pos, n, True)
            return True
        p = self.mp  # compiled: C pointers, the ranges checked above
        _copy(p, base, buf, pos, n)
        last = off + n >= self.length
        self._writer_access(off == 0, last)
        if self.control & SM_CTRL_WATCHDOG:
            self.host.wd_pd_trigger()
        if last and p[self.status_addr + 1] & SM_ACT_LATCH_ECAT:
            self.host.sm_event_time(DC_ECAT_EVENT_TIME)
        return True

    def ecat_read_at(self, off: int, buf: bytearray, pos: int, n: int) -> bool:
        """``ecat_may_read()``, then ``ecat_read(off, buf[pos:pos + n])``, in one call and
        without a view of the data, as ``ecat_write_at`` (decision P61)."""
        if not self.active or self.locked:
            return False
        reader = not self.ecat_side_writes  # else the written SM read back: no side effects
        if reader and self.mailbox and not self.mbx_full:
            return False
        if not reader and self.mailbox:
            return False
        # pointers where every buffer the read may take lies inside the memory and the frame
        if (
            off < 0
            or pos < 0
            or pos + n > len(buf)
            or self.start < 0
            or self.start + (1 if self.mailbox else 3) * self.length + off + n > len(self.mem)
        ):
            self._ecat_checked(off, buf, pos, n, False)
            return True
        first = reader and off == 0
        last = reader and off + n >= self.length
        if first:
            self._reader_open()
        p = self.mp  # compiled: C pointers, the ranges checked above
        _copy(buf, pos, p, self._base_for_read() + off, n)
        if reader:
            self._reader_access(first, last)
            if last and p[self.status_addr + 1] & SM_ACT_LATCH_ECAT:
                self.host.sm_event_time(DC_ECAT_EVENT_TIME)
        return True

    def _ecat_checked(self, off: int, buf: bytearray, pos: int, n: int, write: bool) -> None:
        """``ecat_write`` / ``ecat_read`` of ``buf[pos:pos + n]``: the checked way of
        ``ecat_write_at`` and ``ecat_read_at`` (a method of its own: the view is made here
        only)."""
        view = memoryview(buf)[pos : pos + n]
        if write:
            self.ecat_write(off, view)
        else:
            self.ecat_read(off, view)

    # -- PDI face --------------------------------------------------------------------

    def pdi_may_write(self) -> bool:
        return (not self.ecat_side_writes) and self.writer_may()

    def pdi_may_read(self) -> bool:
        return self.ecat_side_writes and self.reader_may()

    # -- register hooks (ecatsim/esc/dispatch.py: side_effect sm.<name> of SM n's rows;
    # the ECAT writes of start, length, control and activate: the ESC's block hook) ----

    def _pw_pdi_control(self, ra: int, rs: int, old: bytes) -> None:
        """PDI deactivate (bit 0) resets and locks the SM; bit 1 is the repeat ack.
        Ref: TMC8460 §5.49 Table 91."""
        if (self.mem[ra] ^ old[0]) & 0x01:
            self.host.sm_restart(self.n)
