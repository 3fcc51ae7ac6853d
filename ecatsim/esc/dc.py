"""Distributed clocks: local clock, receive-time latching, system time and its control loop.

The local clock is the injected clock plus a per-slave start offset and a configurable
drift (ppm). The time control loop nudges the local copy of the system time towards the
values the master writes to 0x0910 (ARMW/FRMW), as the silicon does with its speed counter.
Ref: TMC8460 §5.50.1 (receive times), §5.50.2 Tables 95-103 (time loop control unit).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from ecatsim.esc.regs import (  # compiled: C constants (dc.pxd)
    CUC_LATCH0_PDI,
    CUC_SYNC_PDI,
    DC_ACTIVATION,
    DC_ACTIVATION_STATUS,
    DC_CYCLIC_UNIT_CONTROL,
    DC_LATCH0_CONTROL,
    DC_LATCH0_POS,
    DC_LATCH0_STATUS,
    DC_NEXT_SYNC1,
    DC_PULSE_LENGTH,
    DC_RECV_TIME_P0,
    DC_RECV_TIME_PU,
    DC_SPEED_COUNTER_DIFF,
    DC_SPEED_COUNTER_START,
    DC_START_TIME,
    DC_SYNC0_CYCLE,
    DC_SYNC0_STATUS,
    DC_SYNC1_CYCLE,
    DC_SYNC1_STATUS,
    DC_SYSTEM_TIME,
    DC_SYSTEM_TIME_DELAY,
    DC_SYSTEM_TIME_DIFF,
    DC_SYSTEM_TIME_OFFSET,
    DC_TIME_DIFF_FILTER,
    ECAT_EV_DC_LATCH,
    ESC_CFG_LATCH_IN,
    ESC_CFG_SYNC_OUT,
    ESC_CONFIG,
    EV_DC_LATCH,
    EV_SYNC0,
    EV_SYNC1,
    SYNC_LATCH_CONFIG,
)

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
MASK64 = (1 << 64) - 1
HALF64 = 1 << 63
HALF32 = 1 << 31
#: a local-clock correction larger than this invalidates cached SYNC deadlines (ns); the
#: segment's pulse hint keeps a larger margin (segment.PULSE_HINT_MARGIN_NS)
MOVE_NS = 50_000
#: the near future of the start time plausibility check (0x0981.6 = 1 / 0). Ref: Table 105
NEAR_FUTURE_SHORT = 1 << 31
NEAR_FUTURE_LONG = 1 << 63
#: DcUnit.port_ns: the frame does not come in at that port; it comes in with a later frame
NO_STAMP = -1
LATER = -2


def _trunc(x: float) -> int:
    """``int(x)``: toward zero (C arithmetic in the compiled core; |x| < 2^63 here)."""
    k = int(x)
    return k


def _signed64(x: int) -> int:
    """``x`` (0 <= x < 2^64) as a two's complement 64-bit value."""
    return x if x < HALF64 else -((MASK64 - x) + 1)


# The register helpers below take DC registers of the 64 KiB memory only: the compiled
# core reaches their bytes through a C pointer, without index checks (decision P27); the
# callers pass the unit's pointer ``mp``, so the helpers cannot raise and no error test
# follows their calls (decision P85).


def _get64(m: bytearray, a: int) -> int:
    """The little-endian 64-bit register at ``a`` (its bytes one by one, unrolled:
    compiled, C reads them as one 64-bit load; decision P60)."""
    p = m  # compiled: a pointer to the bytearray's bytes
    b3 = p[a + 3]  # compiled: 64-bit integers, so bit 31 does not sign-extend
    b7 = p[a + 7]
    lo = p[a] | (p[a + 1] << 8) | (p[a + 2] << 16) | (b3 << 24)
    hi = p[a + 4] | (p[a + 5] << 8) | (p[a + 6] << 16) | (b7 << 24)
    return lo | (hi << 32)


def _get32(m: bytearray, a: int) -> int:
    p = m  # compiled: a pointer, as in _get64
    b3 = p[a + 3]  # compiled: a 64-bit integer, so bit 31 does not sign-extend
    return p[a] | (p[a + 1] << 8) | (p[a + 2] << 16) | (b3 << 24)


def _put64(m: bytearray, a: int, v: int) -> None:
    p = m  # compiled: a pointer, as in _get64; unrolled, one 64-bit store in C
    p[a] = v & 0xFF
    p[a + 1] = (v >> 8) & 0xFF
    p[a + 2] = (v >> 16) & 0xFF
    p[a + 3] = (v >> 24) & 0xFF
    p[a + 4] = (v >> 32) & 0xFF
    p[a + 5] = (v >> 40) & 0xFF
    p[a + 6] = (v >> 48) & 0xFF
    p[a + 7] = (v >> 56) & 0xFF


def _put32(m: bytearray, a: int, v: int) -> None:
    p = m  # compiled: a pointer, as in _get64; unrolled, one 32-bit store in C
    p[a] = v & 0xFF
    p[a + 1] = (v >> 8) & 0xFF
    p[a + 2] = (v >> 16) & 0xFF
    p[a + 3] = (v >> 24) & 0xFF


class DcUnit:
    """Time base and time-loop control of one ESC, and the hooks of its registers
    0x0900-0x09FF (the ESC ``esc`` gives the frame's time and the event registers)."""

    __slots__ = (
        "arrive_ns",
        "drift_ppm",
        "esc",
        "hop_ns",
        "latch_wait",
        "local_ref",
        "mem",
        "moved_ns",
        "mp",
        "next_sync1",
        "port_ns",
        "position",
        "rate_ppb",
        "spd",
        "sync0_at",
        "sync0_on",
        "sync1_countdown",
        "t_ref",
        "turnaround_ns",
    )

    def __init__(
        self,
        esc: Esc,
        position: int,
        *,
        start_ns: int = 0,
        drift_ppm: float = 0.0,
        hop_ns: int = 500,
        turnaround_ns: int = 200,
    ) -> None:
        self.esc = esc
        self.mem = esc.mem
        #: compiled: a pointer to the memory's bytes (fixed: the ESC's view holds the
        #: buffer, so the memory is never resized; decision P85)
        self.mp = self.mem
        self.position = position
        self.drift_ppm = drift_ppm
        self.hop_ns = hop_ns
        self.turnaround_ns = turnaround_ns
        #: when a frame reaches this slave's processing unit, after it entered the segment
        #: (ns); the segment sets it from the route frames take (ecatsim/ethercat/topology.py)
        self.arrive_ns = position * hop_ns
        #: when that frame comes back in at ports 0-3 (ns after it entered; port 0: the
        #: processing unit's time): NO_STAMP where it does not, LATER where it leaves the
        #: process there and a later frame brings it back (the next daemon's reply)
        self.port_ns = [self.arrive_ns, NO_STAMP, NO_STAMP, NO_STAMP]
        #: ports (bit p) whose receive time the next frame entering there latches
        #: (TMC8460 §5.50.2 Table 103, forwarding mode)
        self.latch_wait = 0
        self.rate_ppb = 0.0
        #: local clock ticks per host ns (drift plus the loop's correction), set by _set_rate
        self.spd = 1.0 + drift_ppm * 1e-6
        self.moved_ns = 0  # corrections since the last "deadlines moved"
        # The local clock is piecewise linear: local_ref at host time t_ref, running at
        # spd since. Corrections rebase it, so a rate change never jumps the time.
        self.t_ref = 0
        self.local_ref = start_ns & MASK64
        #: whether a SYNC0 pulse is scheduled, and its system time (``next_sync0``): C
        #: fields, not an int object made at every pulse (decision P42)
        self.sync0_on = False
        self.sync0_at = 0
        #: system time of the next SYNC1 pulse (None: none scheduled), and how many more
        #: SYNC0 pulses until one is scheduled
        self.next_sync1: int | None = None
        self.sync1_countdown = 0

    @property
    def next_sync0(self) -> int | None:
        """System time of the next SYNC0 pulse, or None while the SYNC unit is off."""
        return self.sync0_at if self.sync0_on else None

    @next_sync0.setter
    def next_sync0(self, value: int | None) -> None:
        self.sync0_on = value is not None
        self.sync0_at = value & MASK64 if value is not None else 0

    def arrival_ns(self, frame_t_ns: int) -> int:
        """When a frame sent at ``frame_t_ns`` reaches this slave's port 0."""
        return frame_t_ns + self.arrive_ns

    def local_time(self, t_ns: int) -> int:
        """Local clock at host time ``t_ns`` (drift and control-loop correction applied)."""
        return (self.local_ref + _trunc((t_ns - self.t_ref) * self.spd)) & MASK64

    def _set_rate(self, rate_ppb: float) -> None:
        self.rate_ppb = rate_ppb
        self.spd = 1.0 + self.drift_ppm * 1e-6 + rate_ppb * 1e-9

    def offset(self) -> int:
        return _get64(self.mp, DC_SYSTEM_TIME_OFFSET)

    def system_time(self, t_ns: int) -> int:
        """Local copy of the system time = local time + offset 0x0920. Ref: Table 96."""
        return (self.local_time(t_ns) + self.offset()) & MASK64

    def latch_receive_times(self, frame_t_ns: int) -> None:
        """A write to 0x0900 latches the receive times of port 0 and the processing unit
        at once, and those of ports 1-3 when the frame comes back in there: within this
        frame's walk (the slaves behind the port are in this process), or with the next
        frame entering at that port (the port leads out of the process: stamped by
        :meth:`stamp_port`). Ref: TMC8460 §5.50.1 Tables 92-94, §5.50.2 Table 103 (0x0936
        = 0, forwarding mode: ports 1-3 stamp the next frame after the write)."""
        t0 = self.arrival_ns(frame_t_ns)
        p0 = self.local_time(t0)
        m = self.mem
        _U32.pack_into(m, DC_RECV_TIME_P0, p0 & 0xFFFFFFFF)
        for p in range(1, 4):
            off = self.port_ns[p]
            if off >= 0:
                t = self.local_time(frame_t_ns + off)
                _U32.pack_into(m, DC_RECV_TIME_P0 + 4 * p, t & 0xFFFFFFFF)
            elif off == LATER:
                self.latch_wait |= 1 << p
        _U64.pack_into(m, DC_RECV_TIME_PU, p0)

    def stamp_port(self, port: int, t_ns: int) -> None:
        """A frame came in at ``port`` at host time ``t_ns`` after a latching write.
        Ref: TMC8460 §5.50.1 Table 93."""
        self.latch_wait &= ~(1 << port)
        _U32.pack_into(self.mem, DC_RECV_TIME_P0 + 4 * port, self.local_time(t_ns) & 0xFFFFFFFF)

    def refresh_system_time(self, frame_t_ns: int) -> None:
        """ECAT read of 0x0910: the system time latched at this slave's frame SOF.

        Ref: TMC8460 §5.50.2 Table 95.
        """
        _put64(self.mp, DC_SYSTEM_TIME, self.system_time(self.arrival_ns(frame_t_ns)))

    def latch_system_time(self, t_ns: int) -> None:
        """PDI read of 0x0910: the system time at host time ``t_ns``, latched into the
        register (the DC unit runs whether or not a master uses it).
        Ref: TMC8460 §5.50.2 Table 95.
        """
        _put64(self.mp, DC_SYSTEM_TIME, self.system_time(t_ns))

    def system_time_written(self, frame_t_ns: int, value: int, nbytes: int) -> bool:
        """Compare the written system time with the local copy and feed the control loop.

        The difference is filtered into 0x092C (bit 31: local copy smaller), and 0x0910
        then holds the corrected local copy. A 32-bit write is compared modulo 2^32.
        Returns True once the corrections add up to more than
        MOVE_NS (SYNC deadlines cached in host time are then stale).
        Ref: TMC8460 §5.50.2 Tables 95, 98, 101.
        """
        t = frame_t_ns + self.arrive_ns  # arrival_ns(), local_time() written out (P76)
        p = self.mp  # compiled: a pointer to the registers' bytes (P85)
        delay = _get32(p, DC_SYSTEM_TIME_DELAY)
        offset = _get64(p, DC_SYSTEM_TIME_OFFSET)
        local_now = (self.local_ref + _trunc((t - self.t_ref) * self.spd)) & MASK64
        local = (local_now + offset - delay) & MASK64
        if nbytes < 8:
            diff = ((local - value + HALF32) & 0xFFFFFFFF) - HALF32
        else:
            diff = _signed64((local - value) & MASK64)
        # Proportional step on the time and integral action on the rate: the loop the
        # speed counter implements, with a bandwidth from 0x0930 (larger = smoother).
        start = (p[DC_SPEED_COUNTER_START] | (p[DC_SPEED_COUNTER_START + 1] << 8)) & 0x7FFF
        gain = 1.0 / max(2.0, start / 0x400)
        self.t_ref = t  # rebase at t
        if abs(diff) > 1_000_000:
            step = diff  # far off: jump, as after a new offset
        else:
            step = _trunc(diff * gain)
            self._set_rate(max(-1e6, min(1e6, self.rate_ppb - diff * gain * 5.0)))
        self.local_ref = (local_now - step) & MASK64
        mag = min(abs(diff), 0x7FFFFFFF)
        _put32(p, DC_SYSTEM_TIME_DIFF, mag | (HALF32 if diff < 0 else 0))  # compiled: C ints
        self._speed_counter_diff(start)
        # 0x0910 reads back the corrected local copy (refresh_system_time at time t)
        _put64(p, DC_SYSTEM_TIME, (self.local_ref + offset) & MASK64)
        self.moved_ns += abs(step)
        if self.moved_ns > MOVE_NS:
            self.moved_ns = 0
            return True
        return False

    def host_time_of(self, system_ns: int) -> int:
        """Inverse of system_time(): when the host clock reaches ``system_ns`` here."""
        return self._host_time(system_ns & MASK64)

    def _host_time(self, system_ns: int) -> int:
        """host_time_of() of a system time in [0, 2^64)."""
        local = _signed64((system_ns - self.offset() - self.local_ref) & MASK64)
        return self.t_ref + _trunc(local / self.spd)

    # -- SYNC out unit ---------------------------------------------------------------

    def activation_written(self, now_sys: int) -> None:
        """0x0981 bit 0 starts the SYNC unit at the start time 0x0990; bits 1/2 enable
        SYNC0/SYNC1. ``now_sys`` is the system time of the write.

        The unit waits for the start time; one in the past is reached only after the system
        time wraps (no pulse), unless the plausibility check (bit 5) is on: a start time
        outside the near future (bit 6: 2^31 ns, else 2^63 ns) then starts the pulses at
        once (0x0990 = ``now_sys``) and sets 0x0984.2. Nothing runs while 0x0141.2 has
        the SYNC out unit disabled.
        Ref: TMC8460 §5.50.4 Tables 105, 107, 110; §5.26 Table 38 bit 2; decision R5-5.
        """
        m = self.mem
        act = m[DC_ACTIVATION]
        self.next_sync1 = None
        self.sync1_countdown = 1
        self.next_sync0 = None
        m[DC_ACTIVATION_STATUS] &= 0xF8
        if not (act & 0x01 and act & 0x06 and m[ESC_CONFIG] & ESC_CFG_SYNC_OUT):
            return
        if act & 0x02:
            m[DC_ACTIVATION_STATUS] |= 0x01  # first SYNC0 pulse pending
        if act & 0x04:
            m[DC_ACTIVATION_STATUS] |= 0x02  # first SYNC1 pulse pending
        start = int(_U64.unpack_from(m, DC_START_TIME)[0])
        ahead = (start - now_sys) & MASK64
        near = NEAR_FUTURE_SHORT if act & 0x40 else NEAR_FUTURE_LONG
        if act & 0x20 and ahead >= near:
            m[DC_ACTIVATION_STATUS] |= 0x04  # start time out of the near future
            start = now_sys & MASK64
            _U64.pack_into(m, DC_START_TIME, start)
        elif ahead >= NEAR_FUTURE_LONG:
            return  # in the past: reached after the wrap of the 64-bit system time
        self.next_sync0 = start

    def extend_start_time(self, now_sys: int) -> None:
        """A start time written as 32 bits gets the upper 32 bits that put it nearest to
        ``now_sys`` (within +-2^31 ns). Ref: TMC8460 Table 105 bit 4, Table 110 note."""
        low = int(_U32.unpack_from(self.mem, DC_START_TIME)[0])
        v = (now_sys & ~0xFFFFFFFF) | low
        d = ((v - now_sys + (1 << 63)) & MASK64) - (1 << 63)
        if d >= 1 << 31:
            v -= 1 << 32
        elif d < -(1 << 31):
            v += 1 << 32
        _U64.pack_into(self.mem, DC_START_TIME, v & MASK64)

    def sync0_deadline(self) -> int | None:
        """Host time of the next SYNC0 pulse."""
        return None if self.next_sync0 is None else self.sync0_deadline_or(0)

    def sync0_pulse(self, now_ns: int) -> bool:
        """Generate the due SYNC0 pulse; returns True if SYNC0 is mapped to 0x0220.2.

        Pulses that are more than one cycle overdue (the system time was corrected forward,
        or the host stalled) are skipped rather than fired in a burst.
        Ref: TMC8460 §5.50.4 Tables 106-112; §5.28.2 Table 42 (0x0151 bit 3).
        """
        if not self.sync0_on:
            return False
        p = self.mp  # compiled: a pointer to the registers' bytes (P76, P85)
        n0 = self.sync0_at
        cycle = _get32(p, DC_SYNC0_CYCLE)
        if p[DC_ACTIVATION] & 0x04:
            self._schedule_sync1(n0, cycle)
        if not p[DC_ACTIVATION] & 0x02:
            if cycle:  # SYNC1 only
                self.sync0_at = (n0 + cycle) & MASK64
            else:
                self.sync0_on = False
                self.sync0_at = 0
            return False
        p[DC_ACTIVATION_STATUS] &= 0xFE
        p[DC_SYNC0_STATUS] |= 0x01
        if cycle == 0:
            self.sync0_on = False  # single shot
            self.sync0_at = 0
        else:
            n0 = (n0 + cycle) & MASK64
            # system_time(now_ns) written out: local_time's expression plus 0x0920 (P76)
            local = (self.local_ref + _trunc((now_ns - self.t_ref) * self.spd)) & MASK64
            now_sys = (local + _get64(p, DC_SYSTEM_TIME_OFFSET)) & MASK64
            behind = _signed64((now_sys - n0) & MASK64)
            if behind >= cycle:
                n0 = (n0 + (behind // cycle) * cycle) & MASK64
            self.sync0_at = n0
            _put64(p, DC_START_TIME, n0)
        return bool(p[SYNC_LATCH_CONFIG] & 0x08)

    def reset_sync(self) -> None:
        """Reset: the SYNC unit stops and the time loop forgets its correction (the local
        clock runs on, as the oscillator does). Ref: TMC8460 §5 reset values of 0x0981."""
        self.next_sync0 = None
        self.next_sync1 = None
        self.sync1_countdown = 0
        self._set_rate(0.0)

    def _schedule_sync1(self, sync0_time: int, cycle0: int) -> None:
        """SYNC1 follows SYNC0: every n-th SYNC0 pulse (n = 0x09A4 // 0x09A0, at least 1)
        plus the remainder (0x09A4 mod 0x09A0) as a delay; with SYNC0 single shot, once
        at SYNC0 + 0x09A4. Ref: TMC8460 §5.50.4 Table 113; decision DC5."""
        cycle1 = int(_U32.unpack_from(self.mem, DC_SYNC1_CYCLE)[0])
        self.sync1_countdown -= 1
        if self.sync1_countdown > 0:
            return
        if cycle0:
            self.sync1_countdown = max(1, cycle1 // cycle0)
            self.next_sync1 = sync0_time + cycle1 % cycle0
        else:
            self.next_sync1 = sync0_time + cycle1
        _U64.pack_into(self.mem, DC_NEXT_SYNC1, self.next_sync1 & MASK64)

    def sync0_deadline_or(self, none: int) -> int:
        """sync0_deadline(), or ``none`` while no SYNC0 pulse is scheduled (an integer
        either way: a C integer in the compiled core)."""
        if not self.sync0_on:
            return none
        # _host_time(sync0_at) written out (sync0_at is in [0, 2^64)): C arithmetic
        # without two method calls; the schedule asks several times per pulse (P76)
        offset = _get64(self.mp, DC_SYSTEM_TIME_OFFSET)
        local = _signed64((self.sync0_at - offset - self.local_ref) & MASK64)
        return self.t_ref + _trunc(local / self.spd)

    def sync1_deadline_or(self, none: int) -> int:
        """sync1_deadline(), or ``none`` while no SYNC1 pulse is scheduled."""
        if self.next_sync1 is None:
            return none
        return self.host_time_of(self.next_sync1)

    def sync1_deadline(self) -> int | None:
        """Host time of the next SYNC1 pulse."""
        return None if self.next_sync1 is None else self.sync1_deadline_or(0)

    def sync1_pulse(self) -> bool:
        """Generate the due SYNC1 pulse; True if SYNC1 is mapped to 0x0220.3.
        Ref: TMC8460 §5.50.4 Tables 105, 109; §5.28.2 Table 42 (0x0151 bit 7)."""
        m = self.mem
        self.next_sync1 = None
        m[DC_ACTIVATION_STATUS] &= 0xFD
        m[DC_SYNC1_STATUS] |= 0x01
        return bool(m[SYNC_LATCH_CONFIG] & 0x80)

    # -- latch in unit ----------------------------------------------------------------

    def latch_edge(self, unit: int, rising: bool, host_ns: int) -> bool:
        """An edge on LATCH ``unit``'s input at host time ``host_ns``: capture the system
        time (continuous mode: every edge; single event: the first until the time is read).
        Returns True if a time was captured. Ref: TMC8460 §5.50.5 Tables 114-121.
        """
        m = self.mem
        status = DC_LATCH0_STATUS + unit
        if rising:
            m[status] |= 0x04  # pin state
        else:
            m[status] &= 0xFB
        bit = 0x01 if rising else 0x02
        single = m[DC_LATCH0_CONTROL + unit] & bit
        if single and m[status] & bit:
            return False  # single event: only the first edge until read out
        reg = DC_LATCH0_POS + 16 * unit + (0 if rising else 8)
        _U64.pack_into(m, reg, self.system_time(host_ns))
        if single:
            m[status] |= bit
        return True

    def _speed_counter_diff(self, start: int) -> None:
        """0x0932: the loop's rate correction as the speed counter shows it, solving
        Table 100's deviation = diff / (5 (start + diff + 2)(start - diff + 2)) to first
        order (diff = 5 x deviation x (start + 2)^2), in range +-(start - 0x7F); positive
        when the local clock period is the longer one (the loop speeds it up).
        Ref: TMC8460 §5.50.2 Tables 99, 100; decision R5-7."""
        lim = max(0, start - 0x7F)
        x = _trunc(self.rate_ppb * 5e-9 * (start + 2) * (start + 2))
        x = max(-lim, min(lim, x))
        p = self.mp  # compiled: a pointer to the registers' bytes (P76)
        p[DC_SPEED_COUNTER_DIFF] = x & 0xFF
        p[DC_SPEED_COUNTER_DIFF + 1] = (x >> 8) & 0xFF

    def reset_speed_counter(self) -> None:
        """Writing 0x0930 resets the difference 0x092C and the speed counter: 0x0932 and
        the rate correction it shows. Ref: TMC8460 §5.50.2 Table 99."""
        _U32.pack_into(self.mem, DC_SYSTEM_TIME_DIFF, 0)
        struct.pack_into("<H", self.mem, DC_SPEED_COUNTER_DIFF, 0)
        self._set_rate(0.0)

    def reset_time_difference(self) -> None:
        """Writing 0x0934 resets the system time difference 0x092C. Ref: Table 101."""
        _U32.pack_into(self.mem, DC_SYSTEM_TIME_DIFF, 0)

    # -- register hooks (ecatsim/esc/dispatch.py: side_effect dc.<name>) -----------------

    def _ew_receive_time(self, ra: int, rs: int, old: bytes) -> None:
        """A write to 0x0900 latches the receive times. Ref: TMC8460 §5.50.1 Table 92."""
        if ra == DC_RECV_TIME_P0:
            ctx = self.esc.ctx
            self.latch_receive_times(ctx.t_ns)
            if self.latch_wait:
                ctx.latch_wait = True
        else:
            self.mem[ra : ra + rs] = old

    def _er_system_time(self, ra: int, rs: int) -> None:
        """ECAT read of 0x0910: system time at the frame's SOF. Ref: §5.50.2 Table 95."""
        self.refresh_system_time(self.esc.ctx.t_ns)

    def _pr_system_time(self, ra: int, rs: int) -> None:
        """PDI read of 0x0910: the running system time, latched when the first byte is
        read, at the host time of the PDI access. Ref: TMC8460 §5.50.2 Table 95."""
        self.latch_system_time(self.esc.ctx.pdi_ns)

    def _ew_system_time(self, ra: int, rs: int, old: bytes) -> None:
        """ECAT write of 0x0910 feeds the time control loop, compared only if at least
        the first byte was written. Ref: TMC8460 §5.50.2 Table 95."""
        esc = self.esc
        if esc.wr_s > ra:
            return
        ctx = esc.ctx
        if self.system_time_stored(ctx.t_ns, 8 if esc.wr_e >= ra + 8 else 4):
            ctx.timers_dirty = True  # the clock jumped: SYNC deadlines moved

    def system_time_stored(self, frame_t_ns: int, nbytes: int) -> bool:
        """The ECAT write of ``nbytes`` (4 or 8) of 0x0910 from its first byte, already in
        memory, fed to the time control loop; True if the clock jumped (the ESC calls this
        directly for the writers of every DC cycle, decision P26). Ref: TMC8460 §5.50.2
        Table 95."""
        value = _get64(self.mp, DC_SYSTEM_TIME)  # one load (P76)
        return self.system_time_written(frame_t_ns, value, nbytes)

    def _ec_system_time_offset(self, ra: int, rs: int, old: bytes) -> None:
        """A new offset moves the SYNC deadlines in host time. Ref: TMC8460 §5.50.2 Table 96."""
        self.esc.ctx.timers_dirty = True

    def _ec_system_time_delay(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.2 Table 97 (read where it is used)."""

    def _ew_speed_counter_start(self, ra: int, rs: int, old: bytes) -> None:
        """Writing 0x0930 resets 0x092C and 0x0932. Ref: TMC8460 §5.50.2 Table 99."""
        self.reset_speed_counter()

    def _ew_filter_depth(self, ra: int, rs: int, old: bytes) -> None:
        """Writing 0x0934 resets 0x092C; 0x0935 resets the internal speed counter filter
        only. Ref: TMC8460 §5.50.2 Tables 101, 102."""
        if ra == DC_TIME_DIFF_FILTER:
            self.reset_time_difference()

    def _ec_cyclic_unit_control(self, ra: int, rs: int, old: bytes) -> None:
        """Bit 0: the SYNC out unit, bits 4/5: the latch units, 1 = PDI controlled; the
        owner writes the unit's registers and gets its events (read where they are
        used). Ref: TMC8460 §5.50.3 Table 104."""

    def _ecat_sys_now(self) -> int:
        """The system time at which the frame being processed reaches this ESC."""
        return self.system_time(self.arrival_ns(self.esc.ctx.t_ns))

    def _pdi_sys_now(self) -> int:
        """The system time of the PDI access in progress."""
        return self.system_time(self.esc.ctx.pdi_ns)

    def _sync_owner_is(self, pdi: bool) -> bool:
        """0x0980.0: the SYNC out unit's registers are written by its owner only.
        Ref: TMC8460 §5.50.3 Table 104, notes of Tables 105, 110, 112, 113."""
        return bool(self.mem[DC_CYCLIC_UNIT_CONTROL] & CUC_SYNC_PDI) == pdi

    def _activation(self, ra: int, old: int, now_sys: int) -> None:
        self.mem[ra] &= 0x7F  # bit 7 (debug pulse) self-clearing
        if self.mem[ra] != old:
            self.activation_written(now_sys)
            self.esc.ctx.timers_dirty = True

    def _ec_activation(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.4 Table 105 (written by the SYNC unit's owner, 0x0980.0)."""
        if not self._sync_owner_is(False):
            self.mem[ra] = old[0]
            return
        self._activation(ra, old[0], self._ecat_sys_now())

    def _pw_activation(self, ra: int, rs: int, old: bytes) -> None:
        """The PDI runs the SYNC unit when it owns it (0x0980.0 = 1). Ref: TMC8460
        §5.50.4 Table 105."""
        if not self._sync_owner_is(True):
            self.mem[ra] = old[0]
            return
        self._activation(ra, old[0], self._pdi_sys_now())

    def _pr_sync_status(self, ra: int, rs: int) -> None:
        """PDI read of 0x098E/0x098F clears AL event 0x0220.2/.3; in acknowledge mode (pulse
        length 0x0982 = 0) it also clears the SYNC state bit. Ref: TMC8460 §5.50.4 Tables
        106, 108, 109."""
        self.esc.clr_al_event(self.sync_status_read(ra))

    def sync_status_read(self, ra: int) -> int:
        """The PDI read of 0x098E/0x098F (``ra``) without its AL event: in acknowledge mode
        (pulse length 0x0982 = 0) the SYNC state bit clears; returns the AL event bit the
        read clears (the ESC calls this directly for the firmware's acknowledge of every
        cycle, decision P25). Ref: TMC8460 §5.50.4 Tables 106, 108, 109."""
        m = self.mem
        if not (m[DC_PULSE_LENGTH] | m[DC_PULSE_LENGTH + 1]):
            m[ra] &= 0xFE
        return EV_SYNC0 if ra == DC_SYNC0_STATUS else EV_SYNC1

    def _start_time(self, ra: int, rs: int, old: bytes, pdi: bool, now_sys: int) -> None:
        """Start time: written by the SYNC unit's owner while the unit is off. Written as
        32 bits it is extended to 64 (0x0981.4, or auto-activation 0x0981.3); with
        auto-activation the write starts the unit. Ref: TMC8460 Tables 105, 110."""
        m = self.mem
        act = m[DC_ACTIVATION]
        if act & 0x01 or not self._sync_owner_is(pdi):
            m[ra : ra + rs] = old
            return
        if act & 0x18 and self.esc.wr_e <= ra + 4:
            self.extend_start_time(now_sys)
        if act & 0x08:
            m[DC_ACTIVATION] = act | 0x01
            self._activation(DC_ACTIVATION, act, now_sys)

    def _ew_start_time(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.4 Table 110."""
        self._start_time(ra, rs, old, False, self._ecat_sys_now())

    def _pw_start_time(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.4 Table 110."""
        self._start_time(ra, rs, old, True, self._pdi_sys_now())

    def _ec_cycle_time(self, ra: int, rs: int, old: bytes) -> None:
        """Written by the SYNC unit's owner (0x0980.0). Ref: TMC8460 §5.50.4 Tables 112,
        113."""
        if not self._sync_owner_is(False):
            self.mem[ra : ra + rs] = old

    def _pw_cycle_time(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.4 Tables 112, 113."""
        if not self._sync_owner_is(True):
            self.mem[ra : ra + rs] = old

    def latch_pdi(self, unit: int) -> bool:
        """0x0980.4/.5: latch unit ``unit`` is PDI controlled. Ref: TMC8460 §5.50.3
        Table 104."""
        return bool(self.mem[DC_CYCLIC_UNIT_CONTROL] & (CUC_LATCH0_PDI << unit))

    def _ec_latch_control(self, ra: int, rs: int, old: bytes) -> None:
        """Written by the latch unit's owner (0x0980.4/.5). Ref: TMC8460 §5.50.5 Tables
        114, 115."""
        if self.latch_pdi(ra - DC_LATCH0_CONTROL):
            self.mem[ra] = old[0]

    def _pw_latch_control(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.50.5 Tables 114, 115."""
        if not self.latch_pdi(ra - DC_LATCH0_CONTROL):
            self.mem[ra] = old[0]

    def _latch_time_read(self, ra: int, pdi: bool) -> bool:
        """The owner's read of a latch time clears its event flag; True if no unit of that
        owner has an event flag left. Ref: TMC8460 §5.50.5 Tables 116-121."""
        idx = (ra - DC_LATCH0_POS) // 8
        unit = idx >> 1
        if self.latch_pdi(unit) != pdi:
            return False
        m = self.mem
        m[DC_LATCH0_STATUS + unit] &= ~(1 << (idx & 1)) & 0xFF
        return not any(self.latch_pdi(u) == pdi and m[DC_LATCH0_STATUS + u] & 0x03 for u in (0, 1))

    def _er_latch_time(self, ra: int, rs: int) -> None:
        """ECAT read of an ECAT-controlled latch time clears its status flag, and the DC
        latch event 0x0210.0 once no such flag is left. Ref: TMC8460 §5.50.5 Tables
        118-121; §5.31 Table 45."""
        if self._latch_time_read(ra, False):
            self.esc._clr_ecat_event(ECAT_EV_DC_LATCH)

    def _pr_latch_time(self, ra: int, rs: int) -> None:
        """PDI read of a PDI-controlled latch time clears its status flag, and AL event
        0x0220.1 once no such flag is left. Ref: TMC8460 §5.50.5 Tables 118-121 note *;
        §5.32 Table 46 bit 1."""
        if self._latch_time_read(ra, True):
            self.esc.clr_al_event(EV_DC_LATCH)

    def latch_input(self, unit: int, level: bool, host_ns: int) -> None:
        """The LATCH ``unit`` pin is driven to ``level`` at host time ``host_ns``. The
        latch inputs work beside the SYNC outputs whatever 0x0151 bits 2/6 say (Table 42
        note *), while 0x0141.3 has the latch in unit enabled. A captured edge raises the
        DC latch event of the unit's owner: ECAT 0x0210.0 or AL 0x0220.1 (0x0980.4/.5).
        Ref: TMC8460 §5.28.2 Table 42, §5.26 Table 38, §5.50.3 Table 104, §5.50.5."""
        m = self.mem
        if not m[ESC_CONFIG] & ESC_CFG_LATCH_IN:
            return  # the latch in unit is disabled (power saving)
        if bool(m[DC_LATCH0_STATUS + unit] & 0x04) == level:
            return  # no edge
        if self.latch_edge(unit, level, host_ns):
            if self.latch_pdi(unit):
                self.esc.set_al_event(EV_DC_LATCH)
            else:
                self.esc._set_ecat_event(ECAT_EV_DC_LATCH)

    def esc_config_loaded(self) -> None:
        """After an EEPROM reload: a SYNC out unit that 0x0141.2 now disables stops.
        Ref: TMC8460 §5.26 Table 38 bit 2."""
        if not self.mem[ESC_CONFIG] & ESC_CFG_SYNC_OUT and (
            self.next_sync0 is not None or self.next_sync1 is not None
        ):
            self.next_sync0 = self.next_sync1 = None
            self.mem[DC_ACTIVATION_STATUS] &= 0xFC
            self.esc.ctx.timers_dirty = True
