"""SII EEPROM interface 0x0500-0x050F: ownership, command machine, load and reload.

Commands complete within the frame that issues them, so the busy bit is never seen
set by a later datagram. Ref: TMC8460 §5.45 Tables 59-65, §3.7; ETG.2010 (SII layout).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import TYPE_CHECKING

from ecatsim.esc import regs
from ecatsim.sii.crc import crc8

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")

CMD_MASK = 0x0700
CMD_NOP = 0x0000
CMD_READ = 0x0100
CMD_WRITE = 0x0200
CMD_RELOAD = 0x0400
ST_WRITE_ENABLE = 0x0001
ST_READ_8 = 0x0040
ST_TWO_ADDR_BYTES = 0x0080
ST_CHECKSUM_ERROR = 0x0800
ST_NOT_LOADED = 0x1000
ST_ACK_ERROR = 0x2000
ST_WE_ERROR = 0x4000
ST_BUSY = 0x8000

#: The MFCIO configuration: a category of type 1 as the first category (word 0x40) is
#: copied into the parameter RAM 0x0580:0x05AB, one byte per register, bits 4..0.
#: Ref: TMC8460 §6.3 Table 134, §5.47 Table 74; decision M1.
MFCIO_CATEGORY_WORD = 0x40
MFCIO_CATEGORY_TYPE = 1
MFCIO_CONFIG = 0x0580
MFCIO_CONFIG_SIZE = 44

#: ESC configuration area words copied into registers on load. Ref: ETG.2010 Table 2.
CONFIG_WORDS = (
    (0, regs.PDI_CONTROL),
    (1, regs.PDI_CONFIG),
    (2, regs.DC_PULSE_LENGTH),
    (3, regs.PDI_CONFIG_EXT),
)


class EepromUnit:
    """The ESC side of the SII EEPROM (an I2C EEPROM behind the ESC, not emulation), and
    the hooks of its registers 0x0500-0x050F (the ESC ``esc`` gives the frame and the
    write range)."""

    __slots__ = ("esc", "image", "mem", "on_write", "we_frame")

    def __init__(
        self, esc: Esc, image: bytearray, on_write: Callable[[], None] | None = None
    ) -> None:
        self.esc = esc
        self.mem = esc.mem
        self.image = image
        self.on_write = on_write
        self.we_frame = -1

    # -- helpers --------------------------------------------------------------------

    def _status(self) -> int:
        return int(_U16.unpack_from(self.mem, regs.EEPROM_CONTROL)[0])

    def _set_status(self, v: int) -> None:
        _U16.pack_into(self.mem, regs.EEPROM_CONTROL, v & 0xFFFF)

    def pdi_owns(self) -> bool:
        """PDI controls the interface if 0x0500.0 or 0x0501.0 is set. Ref: §5.45."""
        return bool((self.mem[regs.EEPROM_CONFIG] | self.mem[regs.EEPROM_PDI_ACCESS]) & 1)

    def _word(self, addr: int) -> int:
        n = len(self.image) // 2
        if n == 0:
            return 0xFFFF
        a = (addr % n) * 2
        return self.image[a] | (self.image[a + 1] << 8)

    # -- load -----------------------------------------------------------------------

    def checksum_ok(self) -> bool:
        """CRC-8 over words 0-6 must equal the low byte of word 7. Ref: ETG.2010 §2.1."""
        img = self.image
        return len(img) >= 16 and crc8(bytes(img[0:14])) == img[14]

    def load(self, first: bool) -> bool:
        """Load the ESC configuration area into the registers (power-on or reload).

        Returns True if the checksum was good. On a checksum error nothing is taken
        over, 0x0502.11 and .12 are set and the PD RAM stays inaccessible. Word 0 goes to
        0x0140/0x0141 at every load; the alias (word 4), enhanced link detection 0x0110.2
        (word 0 bit 9 or bits 15:12) and the FIFO size (word 5) only at the ``first`` one
        (the first good load since power-on or reset).
        Ref: TMC8460 §5.45 Table 62 bits 11/12, §5.19 Table 30 bits 0/2, §5.10, §5.17,
        §5.26 Table 38.
        """
        st = self._status() & ~(ST_CHECKSUM_ERROR | ST_NOT_LOADED | CMD_MASK | ST_BUSY)
        if len(self.image) > 2048:  # more than 16 kbit: two address bytes
            st |= ST_TWO_ADDR_BYTES
        if not self.checksum_ok():
            self._set_status(st | ST_CHECKSUM_ERROR | ST_NOT_LOADED)
            self.mem[regs.DL_STATUS] &= 0xFE
            return False
        m = self.mem
        for word, reg in CONFIG_WORDS:
            v = self._word(word)
            m[reg] = v & 0xFF
            m[reg + 1] = v >> 8
        if first:
            _U16.pack_into(m, regs.STATION_ALIAS, self._word(4))
            w5 = self._word(5)
            fifo = ((~w5 >> 9) & 0x7) if w5 != 0xFFFF else 7
            m[regs.DL_CONTROL + 2] = (m[regs.DL_CONTROL + 2] & 0xF8) | fifo
            enhanced = self._word(0) & 0xF200
            m[regs.DL_STATUS] = (m[regs.DL_STATUS] & 0xFB) | (0x04 if enhanced else 0)
        self._load_mfcio_config()
        m[regs.PDI_INFORMATION] = (m[regs.PDI_INFORMATION] & ~0x0E) | 0x06  # configured, active
        m[regs.DL_STATUS] |= 0x01
        self._set_status(st)
        return True

    def _load_mfcio_config(self) -> None:
        """Category type 1 at word 0x40: its data (the category length is in words, as in
        every SII category) fills 0x0580 onwards; bytes it leaves out take the reset value
        0x00, reserved bits 7..5 read 0. Without such a category the parameter RAM keeps
        its content. Ref: TMC8460 §6.3, §6.4 ("trailing bytes can be omitted"), §5.47."""
        if self._word(MFCIO_CATEGORY_WORD) != MFCIO_CATEGORY_TYPE:
            return
        n = min(2 * self._word(MFCIO_CATEGORY_WORD + 1), MFCIO_CONFIG_SIZE)
        start = (MFCIO_CATEGORY_WORD + 2) * 2
        data = bytes(b & 0x1F for b in self.image[start : start + n])
        self.mem[MFCIO_CONFIG : MFCIO_CONFIG + MFCIO_CONFIG_SIZE] = data.ljust(
            MFCIO_CONFIG_SIZE, b"\x00"
        )

    # -- the command machine (ECAT's or the PDI's) -------------------------------------

    def ecat_config_written(self, frame_no: int) -> None:
        """0x0500 bit 1 forces ECAT access: clears 0x0501.0. Ref: §5.45 Table 60."""
        if self.mem[regs.EEPROM_CONFIG] & 0x02:
            self.mem[regs.EEPROM_PDI_ACCESS] &= 0xFE
        self.ownership_changed(frame_no)

    def ownership_changed(self, frame_no: int) -> None:
        """0x0502.0 is always 1 while the PDI has EEPROM control; with ECAT in control it
        is ECAT's write enable of this frame. Ref: TMC8460 §5.45 Table 62 bit 0."""
        if self.pdi_owns():
            self.mem[regs.EEPROM_CONTROL] |= ST_WRITE_ENABLE
        else:
            self.ecat_refresh_status(frame_no)

    def ecat_refresh_status(self, frame_no: int) -> None:
        """Write enable self-clears at the start of the next frame. Ref: §5.45 Table 62 note *."""
        if self.we_frame != frame_no and not self.pdi_owns():
            self.mem[regs.EEPROM_CONTROL] &= ~ST_WRITE_ENABLE & 0xFF

    def control_written(self, old: int, frame_no: int, wrote_cmd: bool, pdi: bool) -> bool:
        """Run the command written to 0x0502 by ECAT or, while it has EEPROM control, by
        the PDI (its write enable is always 1); return True if the image changed.

        Ref: TMC8460 §5.45 Table 62 (commands 000/001/010/100, error bits, write enable,
        r/(w): write access depends upon the assignment of the EEPROM interface).
        """
        new = self._status()
        if self.pdi_owns() != pdi:
            self._set_status(old)
            return False
        if pdi or new & ST_WRITE_ENABLE:
            self.we_frame = frame_no
        if not wrote_cmd:
            return False
        cmd = new & CMD_MASK
        st = (old & ~(CMD_MASK | ST_WRITE_ENABLE)) | (new & ST_WRITE_ENABLE)
        changed = False
        if cmd == CMD_NOP:
            st &= ~(ST_ACK_ERROR | ST_WE_ERROR)
        elif old & ST_ACK_ERROR:
            pass  # commands are ignored while an acknowledge error is pending
        elif cmd == CMD_READ:
            st &= ~ST_WE_ERROR
            addr = _U32.unpack_from(self.mem, regs.EEPROM_ADDRESS)[0]
            m = self.mem
            _U16.pack_into(m, regs.EEPROM_DATA, self._word(addr))
            _U16.pack_into(m, regs.EEPROM_DATA + 2, self._word(addr + 1))
            m[regs.EEPROM_DATA + 4 : regs.EEPROM_DATA + 8] = b"\x00\x00\x00\x00"
        elif cmd == CMD_WRITE:
            if self.we_frame != frame_no and not pdi:
                st |= ST_WE_ERROR
            else:
                st &= ~ST_WE_ERROR
                addr = _U32.unpack_from(self.mem, regs.EEPROM_ADDRESS)[0]
                n = len(self.image) // 2
                if n:
                    a = (addr % n) * 2
                    self.image[a : a + 2] = self.mem[regs.EEPROM_DATA : regs.EEPROM_DATA + 2]
                    changed = True
        elif cmd == CMD_RELOAD:
            st &= ~ST_WE_ERROR
            self._set_status(st)
            self.load(first=bool(old & ST_NOT_LOADED))  # the first good load since reset
            st = self._status()
        else:
            st |= ST_ACK_ERROR
        self._set_status(st)
        if changed and self.on_write is not None:
            self.on_write()
        return changed

    def data_written(self, reg: int, old: bytes, pdi: bool) -> None:
        """Address and data registers are writable by the side that owns the interface
        (ECAT or the PDI). Ref: §5.45 Tables 63, 64 (r/(w))."""
        if self.pdi_owns() != pdi:
            self.mem[reg : reg + len(old)] = old

    # -- register hooks (ecatsim/esc/dispatch.py: side_effect eeprom.<name>) -------------

    def _ew_config(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 60."""
        self.ecat_config_written(self.esc.ctx.frame_no)

    def _pw_pdi_access(self, ra: int, rs: int, old: bytes) -> None:
        """PDI may take the EEPROM only if offered (0x0500.0 = 1, .1 = 0). Ref: TMC8460
        §5.45 Table 61."""
        cfg = self.mem[regs.EEPROM_CONFIG]
        if not (cfg & 0x01) or cfg & 0x02:
            self.mem[ra] = old[0]
        self.ownership_changed(self.esc.ctx.frame_no)

    def _control(self, ra: int, old: bytes, pdi: bool) -> None:
        esc = self.esc
        wrote_cmd = esc.wr_s <= ra + 1 < esc.wr_e
        self.control_written(old[0] | (old[1] << 8), esc.ctx.frame_no, wrote_cmd, pdi)
        esc.dc.esc_config_loaded()

    def _ew_control(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 62."""
        self._control(ra, old, False)

    def _pw_control(self, ra: int, rs: int, old: bytes) -> None:
        """The PDI runs the command machine while it has EEPROM control (0x0500.0 or
        0x0501.0). Ref: TMC8460 §5.45 Tables 59-62."""
        self._control(ra, old, True)

    def _er_control(self, ra: int, rs: int) -> None:
        """Ref: TMC8460 §5.45 Table 62 note * (write enable self-clears)."""
        self.ecat_refresh_status(self.esc.ctx.frame_no)

    def _ew_address(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 63."""
        self.data_written(ra, old, False)

    def _pw_address(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 63."""
        self.data_written(ra, old, True)

    def _ew_data(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 64."""
        self.data_written(ra, old, False)

    def _pw_data(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.45 Table 64."""
        self.data_written(ra, old, True)
