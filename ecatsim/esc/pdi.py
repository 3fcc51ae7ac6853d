"""The PDI face of the ESC: what the firmware behind the SPI PDI can see and do.

Firmware (``ecatsim.slave``) and devices import the ESC only through this module, in
Python and in the compiled core alike (``pdi.pxd`` is the only ``.pxd`` the firmware's
declarations cimport). Accesses follow the PDI
columns of the register table and the PDI side of the SyncManagers.
Ref: TMC8460 §2.3.2, §3.5 (PDI SPI), §5 (PDI access columns).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ecatsim.esc import regs
from ecatsim.esc.regs import (  # re-exported for the firmware
    AL_CONTROL,
    AL_EVENT_MASK,
    AL_EVENT_REQUEST,
    AL_STATUS,
    AL_STATUS_CODE,
    DC_ACTIVATION,
    DC_ACTIVATION_STATUS,
    DC_LATCH0_POS,
    DC_LATCH1_POS,
    DC_NEXT_SYNC1,
    DC_START_TIME,
    DC_SYNC0_STATUS,
    DC_SYNC1_STATUS,
    DL_STATUS,
    ESC_CONFIG,
    EV_AL_CONTROL,
    EV_SM0,
    EV_SM_ACTIVATION,
    EV_SYNC0,
    EV_SYNC1,
    EV_WATCHDOG_PD,
    N_SM,
    SM_CTRL_PDI_IRQ,
    WD_STATUS_PD,
    sm_addr,
)
from ecatsim.esc.regs import DC_SYNC0_STATUS as _SYNC0_STATUS  # compiled: C constants
from ecatsim.esc.regs import DC_SYNC1_STATUS as _SYNC1_STATUS  # (pdi.pxd)
from ecatsim.esc.regs import DL_STATUS as _DL_STATUS
from ecatsim.esc.regs import REGISTER_END as _REG_END

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc
    from ecatsim.esc.sm import SyncManager

__all__ = [
    "AL_CONTROL",
    "AL_EVENT_MASK",
    "AL_EVENT_REQUEST",
    "AL_STATUS",
    "AL_STATUS_CODE",
    "DC_ACTIVATION",
    "DC_ACTIVATION_STATUS",
    "DC_LATCH0_POS",
    "DC_LATCH1_POS",
    "DC_NEXT_SYNC1",
    "DC_START_TIME",
    "DC_SYNC0_STATUS",
    "DC_SYNC1_STATUS",
    "DL_STATUS",
    "ESC_CONFIG",
    "EV_AL_CONTROL",
    "EV_SM0",
    "EV_SM_ACTIVATION",
    "EV_SYNC0",
    "EV_SYNC1",
    "EV_WATCHDOG_PD",
    "N_SM",
    "SM_CTRL_PDI_IRQ",
    "WD_STATUS_PD",
    "Pdi",
    "SmImage",
    "SmSettings",
    "sm_addr",
]

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")


@dataclass(frozen=True, slots=True)
class SmSettings:
    """What the master programmed into SyncManager n (0x0800+8n). Ref: §5.49 Table 85."""

    start: int
    length: int
    control: int
    enabled: bool
    pdi_deactivated: bool


class SmImage:
    """A process image that fills an SM's whole buffer in place (``Pdi.sm_fill``), as an
    SPI burst puts its bytes straight into the ESC's buffer: no bytes object between the
    firmware and the SM (decision P71). Ref: TMC8460 §5.49 (PDI side of a 3-buffer SM)."""

    __slots__ = ()

    def fill(self, mem: bytearray, base: int, n: int) -> bool:
        """Write the image's ``n`` bytes to ``mem[base:base + n]`` (every byte, padding
        zero), or touch nothing and return False: the caller then writes the bytes the
        general way (``Pdi.sm_write``)."""
        return False


class Pdi:
    """PDI access to one ESC (register reads/writes with PDI rights, SM PDI side)."""

    __slots__ = ("_esc",)

    def __init__(self, esc: Esc) -> None:
        self._esc = esc

    @property
    def position(self) -> int:
        return self._esc.position

    def latch_input(self, unit: int, level: bool, host_ns: int) -> None:
        """Drive the LATCH ``unit`` input pin (the application's signal, e.g. an encoder
        index pulse) at host time ``host_ns``. Ref: TMC8460 §5.50.5."""
        self._esc.latch_input(unit, level, host_ns)

    def frames(self) -> tuple[int, int]:
        """The frames the ESC has seen and the arrival time of the latest: the start/end
        of frame signals the MFCIO block takes from the ESC beside the PDI (TMC8460 §6.1,
        §6.4 Table 136 triggers 5/6, §6.11.2 cfg_sof_enable)."""
        ctx = self._esc.ctx
        return ctx.frame_no, ctx.t_ns

    def access_time(self, now_ns: int) -> None:
        """The host time of the PDI accesses that follow (an external microcontroller's
        SPI transfer): the time base of PDI-side DC event times (§5.50.6) and activations."""
        self._esc.ctx.pdi_ns = now_ns

    def operational(self) -> bool:
        """DL status 0x0110.0: EEPROM loaded, PDI operational. Ref: §5.19 Table 30."""
        return bool(self._esc.mem[_DL_STATUS] & 0x01)

    # -- raw access with PDI rules ----------------------------------------------------

    def read(self, addr: int, n: int) -> bytes:
        """PDI read of ``n`` bytes (SM windows redirected; PDI read side effects run)."""
        esc = self._esc
        end = addr + n
        if addr >= _REG_END:  # SM windows lie in process RAM only (decision E22)
            for ws, we, sm in esc.sm_windows:
                if ws <= addr and end <= we:
                    if not sm.pdi_may_read():
                        return bytes(n)
                    out = bytearray(n)
                    sm.reader_read(addr - ws, memoryview(out))
                    esc.pdi_buffer_event(sm, addr == ws, end - ws >= sm.length)
                    return bytes(out)
            if not esc.pdram_ok:
                return bytes(n)
            return bytes(esc.mem[addr:end]).ljust(n, b"\x00")  # past 0xFFFF: zeros
        esc.reg_read_hooks(addr, min(end, _REG_END), True)
        return bytes(esc.mem[addr:end]).ljust(n, b"\x00")

    def write(self, addr: int, data: bytes) -> bool:
        """PDI write (SM windows redirected; masks and PDI write side effects apply).

        Returns False if an SM refused the access (mailbox full, wrong direction).
        """
        esc = self._esc
        n = len(data)
        end = addr + n
        for ws, we, sm in esc.sm_windows:
            if ws <= addr and end <= we:
                if not sm.pdi_may_write():
                    return False
                sm.writer_write(addr - ws, data)
                esc.pdi_buffer_event(sm, addr == ws, end - ws >= sm.length)
                return True
        if addr >= _REG_END:
            if not esc.pdram_ok:
                return False
            mem = esc.mem
            if end > len(mem):  # the address space ends at 0xFFFF: the rest is lost
                data = data[: len(mem) - addr]
                end = len(mem)
            mem[addr:end] = data
            return True
        if end > _REG_END:  # the registers' part masked, the rest is process RAM
            split = _REG_END - addr
            esc.reg_write(addr, bytes(data[:split]), True)
            if esc.pdram_ok:
                esc.mem[_REG_END:end] = data[split:]
            return True
        esc.reg_write(addr, bytes(data), True)
        return True

    # -- typed helpers -------------------------------------------------------------

    # A register without a PDI read side effect is read straight from memory: registers
    # are never behind an SM window (decision E22), so only the hooks make a difference.

    def u8(self, addr: int) -> int:
        esc = self._esc
        if addr < _REG_END:  # a register: its read side effects, then the byte
            hooked: bytes = esc.pdi_r_hooked
            if hooked[addr]:
                if addr in (_SYNC0_STATUS, _SYNC1_STATUS):
                    # the acknowledge of every SYNC pulse: the registers' one hook
                    # (DcUnit._pr_sync_status) as reg_read_hooks runs it (P25, P44)
                    esc.clr_al_event(esc.dc.sync_status_read(addr))
                else:
                    esc.reg_read_hooks(addr, addr + 1, True)
            return esc.mem[addr]
        return self.read(addr, 1)[0]

    def u16(self, addr: int) -> int:
        esc = self._esc
        hooked: bytes = esc.pdi_r_hooked
        if addr + 2 <= _REG_END and not (hooked[addr] or hooked[addr + 1]):
            m = esc.mem
            return m[addr] | (m[addr + 1] << 8)
        return int(_U16.unpack(self.read(addr, 2))[0])

    def u32(self, addr: int) -> int:
        esc = self._esc
        if addr + 4 <= _REG_END and esc.t.pdi_r_hooked.find(1, addr, addr + 4) < 0:
            m = esc.mem
            b3 = m[addr + 3]  # compiled: a 64-bit integer, so bit 31 does not sign-extend
            return m[addr] | (m[addr + 1] << 8) | (m[addr + 2] << 16) | (b3 << 24)
        return int(_U32.unpack(self.read(addr, 4))[0])

    def w16(self, addr: int, value: int) -> None:
        self.write(addr, _U16.pack(value & 0xFFFF))

    def w32(self, addr: int, value: int) -> None:
        self.write(addr, _U32.pack(value & 0xFFFFFFFF))

    def al_event(self) -> int:
        """AL event request 0x0220 (reading it has no side effect). Ref: §5.32."""
        return self._esc.al_event()

    # -- the SPI slave interface (TMC8460 §3.5) ------------------------------------------

    def events(self) -> bytes:
        """AL event request 0x0220:0x0222, as the SPI slave shifts it out during the
        address phase (no read side effects). Ref: §3.5.1, §5.32."""
        return bytes(self._esc.mem[regs.AL_EVENT_REQUEST : regs.AL_EVENT_REQUEST + 3])

    def interface_error(self, code: int) -> None:
        """An SPI access with an interface error (counted in 0x030D, code in 0x030E)."""
        self._esc.pdi_interface_error(code)

    def watchdog_pdi_ns(self) -> int:
        """The PDI watchdog time: 0x0410 increments of (0x0400 + 2) x 40 ns; 0 = off.
        Ref: §5.39 Table 53, §5.40 Table 54."""
        m = self._esc.mem
        div = m[regs.WD_DIVIDER] | (m[regs.WD_DIVIDER + 1] << 8)
        t = m[regs.WD_TIME_PDI] | (m[regs.WD_TIME_PDI + 1] << 8)
        return t * (div + 2) * 40

    def set_watchdog_pdi(self, alive: bool) -> None:
        """Reload (True) or expire (False) the PDI watchdog (0x0110 bit 1, 0x0443)."""
        self._esc.set_pdi_watchdog(alive)

    # -- SyncManager PDI side --------------------------------------------------------

    def sm_settings(self, n: int) -> SmSettings:
        """Read SM n's configuration registers. Ref: §5.49 Tables 86-91."""
        raw = self.read(sm_addr(n), 8)
        start, length = struct.unpack_from("<HH", raw)
        return SmSettings(start, length, raw[4], bool(raw[6] & 1), bool(raw[7] & 1))

    def sm_read(self, n: int) -> bytes | None:
        """Read SM n's whole buffer from the PDI side, or None if not readable now."""
        esc = self._esc
        sm: SyncManager = esc.sm[n]
        if not sm.pdi_may_read():
            return None
        data = sm.read_whole()
        esc.pdi_buffer_event(sm, True, True)
        return data

    def sm_write(self, n: int, data: bytes) -> bool:
        """Write SM n's whole buffer from the PDI side (padded/truncated to its length)."""
        esc = self._esc
        sm: SyncManager = esc.sm[n]
        if not sm.pdi_may_write():
            return False
        if len(data) != sm.length:
            data = bytes(data[: sm.length]).ljust(sm.length, b"\x00")
        sm.write_whole(data)
        esc.pdi_buffer_event(sm, True, True)
        return True

    def sm_read_into(self, n: int, out: bytearray) -> bool:
        """``sm_read`` into ``out`` (the same bytes, ``out`` taking their length), for a
        caller that keeps one buffer for SM n's data; False (``out`` untouched) if not
        readable now (decision P70)."""
        esc = self._esc
        sm: SyncManager = esc.sm[n]
        if not sm.pdi_may_read():
            return False
        sm.read_into(out)
        esc.pdi_buffer_event(sm, True, True)
        return True

    def sm_fill(self, n: int, image: SmImage) -> bool:
        """``sm_write`` of ``image``'s bytes filled straight into SM n's buffer (decision
        P71): the same bytes, buffer exchange and events. False, with nothing done, where
        ``sm_write`` must write them: SM n not writable now, its length not the image's
        (padded or truncated there), its buffer not inside the memory, or ``image.fill``
        declines."""
        esc = self._esc
        sm: SyncManager = esc.sm[n]
        if not sm.pdi_may_write():
            return False
        size = sm.length
        base = sm.whole_base(size)
        if base < 0 or not image.fill(esc.mem, base, size):
            return False
        sm.written()
        esc.pdi_buffer_event(sm, True, True)
        return True

    def sm_deactivate(self, n: int, off: bool) -> None:
        """Set or clear the PDI deactivate bit 0x0807+8n.0. Ref: §5.49 Table 91."""
        a = sm_addr(n, 7)
        v = self.u8(a)
        self.write(a, bytes([(v | 1) if off else (v & ~1)]))

    def sm_repeat_request(self, n: int) -> bool:
        """The master's repeat request bit 0x0806+8n.1. Ref: §5.49 Table 90."""
        return bool(self.read(sm_addr(n, 6), 1)[0] & 0x02)

    def sm_repeat_ack(self, n: int, value: bool) -> None:
        """Write the repeat ack bit 0x0807+8n.1. Ref: §5.49 Table 91."""
        a = sm_addr(n, 7)
        v = self.u8(a)
        self.write(a, bytes([(v | 2) if value else (v & ~2)]))
