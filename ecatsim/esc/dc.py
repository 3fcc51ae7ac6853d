"""Distributed clocks: local clock, receive-time latching, system time and its control loop.

The local clock is the injected clock plus a per-slave start offset and a configurable
drift (ppm). The time control loop nudges the local copy of the system time towards the
values the master writes to 0x0910 (ARMW/FRMW), as the silicon does with its speed counter.
Ref: TMC8460 §5.50.1 (receive times), §5.50.2 Tables 95-103 (time loop control unit).
"""

from __future__ import annotations

import struct

from ecatsim.esc import regs

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
MASK64 = (1 << 64) - 1


class DcUnit:
    """Time base and time-loop control of one ESC."""

    __slots__ = (
        "adjust_ns",
        "drift_ppm",
        "hop_ns",
        "mem",
        "position",
        "rate_ppb",
        "start_ns",
        "turnaround_ns",
    )

    def __init__(
        self,
        mem: bytearray,
        position: int,
        *,
        start_ns: int = 0,
        drift_ppm: float = 0.0,
        hop_ns: int = 500,
        turnaround_ns: int = 200,
    ) -> None:
        self.mem = mem
        self.position = position
        self.start_ns = start_ns
        self.drift_ppm = drift_ppm
        self.hop_ns = hop_ns
        self.turnaround_ns = turnaround_ns
        self.adjust_ns = 0.0
        self.rate_ppb = 0.0

    def arrival_ns(self, frame_t_ns: int) -> int:
        """When a frame sent at ``frame_t_ns`` reaches this slave's port 0."""
        return frame_t_ns + self.position * self.hop_ns

    def local_time(self, t_ns: int) -> int:
        """Local clock at host time ``t_ns`` (drift and control-loop correction applied)."""
        drift = t_ns * (self.drift_ppm * 1e-6 + self.rate_ppb * 1e-9)
        return (self.start_ns + t_ns + int(drift + self.adjust_ns)) & MASK64

    def offset(self) -> int:
        return int(_U64.unpack_from(self.mem, regs.DC_SYSTEM_TIME_OFFSET)[0])

    def system_time(self, t_ns: int) -> int:
        """Local copy of the system time = local time + offset 0x0920. Ref: Table 96."""
        return (self.local_time(t_ns) + self.offset()) & MASK64

    def latch_receive_times(self, frame_t_ns: int, slaves_behind: int) -> None:
        """A write to 0x0900 latches port 0, port 1 and processing-unit receive times.

        Port 1 sees the frame coming back from the slaves behind this one.
        Ref: TMC8460 §5.50.1 Tables 92-94.
        """
        t0 = self.arrival_ns(frame_t_ns)
        p0 = self.local_time(t0)
        m = self.mem
        _U32.pack_into(m, regs.DC_RECV_TIME_P0, p0 & 0xFFFFFFFF)
        if slaves_behind > 0:
            back = 2 * slaves_behind * self.hop_ns + self.turnaround_ns
            _U32.pack_into(m, regs.DC_RECV_TIME_P1, self.local_time(t0 + back) & 0xFFFFFFFF)
        _U64.pack_into(m, regs.DC_RECV_TIME_PU, p0)

    def refresh_system_time(self, frame_t_ns: int) -> None:
        """ECAT read of 0x0910: the system time latched at this slave's frame SOF.

        Ref: TMC8460 §5.50.2 Table 95.
        """
        _U64.pack_into(self.mem, regs.DC_SYSTEM_TIME, self.system_time(self.arrival_ns(frame_t_ns)))

    def system_time_written(self, frame_t_ns: int, value: int, nbytes: int) -> None:
        """Compare the written system time with the local copy and feed the control loop.

        The difference is filtered into 0x092C (bit 31: local copy smaller). A 32-bit write
        is compared modulo 2^32. Ref: TMC8460 §5.50.2 Tables 95, 98, 101.
        """
        delay = int(_U32.unpack_from(self.mem, regs.DC_SYSTEM_TIME_DELAY)[0])
        local = self.system_time(self.arrival_ns(frame_t_ns)) - delay
        if nbytes < 8:
            diff = ((local - value + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)
        else:
            diff = ((local - value + (1 << 63)) & MASK64) - (1 << 63)
        # Proportional step on the time and integral action on the rate: the loop the
        # speed counter implements, with a bandwidth from 0x0930 (larger = smoother).
        start = int(struct.unpack_from("<H", self.mem, regs.DC_SPEED_COUNTER_START)[0]) & 0x7FFF
        gain = 1.0 / max(2.0, start / 0x400)
        if abs(diff) > 1_000_000:
            self.adjust_ns -= diff  # far off: jump, as after a new offset
        else:
            self.adjust_ns -= diff * gain
            self.rate_ppb -= diff * gain * 0.05
        mag = min(abs(diff), 0x7FFFFFFF)
        _U32.pack_into(self.mem, regs.DC_SYSTEM_TIME_DIFF, mag | (0x80000000 if diff < 0 else 0))

    def reset_filters(self) -> None:
        """Writing 0x0930/0x0934 resets the difference and speed counter diff. Ref: Table 99."""
        _U32.pack_into(self.mem, regs.DC_SYSTEM_TIME_DIFF, 0)
        struct.pack_into("<H", self.mem, regs.DC_SPEED_COUNTER_DIFF, 0)
