"""MII management interface 0x0510-0x051B: ownership, command machine and the PHYs behind it.

The TMC8460 reaches its two Ethernet PHYs over MCLK/MDIO at PHY address offset + logical
port (§3.4.2, PHY_OFFSET). A command written to 0x0510[9:8] completes within the access
that issues it, so the busy bit is never seen set. The PHYs are modelled as IEEE 802.3
clause 22 register files of an IP101GA (one of the PHYs §3.4 lists as tested).
Ref: TMC8460 §5.46 Tables 66-73, §3.4; IEEE 802.3 clause 22 (PHY registers 0-6).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ecatsim.esc import regs

if TYPE_CHECKING:
    from ecatsim.esc.core import Esc

# 0x0510 MII management control/status. Ref: TMC8460 §5.46 Table 67.
WRITE_ENABLE = 0x0001
PDI_CONTROL_POSSIBLE = 0x0002
PORT0_ADDR_SHIFT = 3
PORT0_ADDR_MASK = 0x00F8
CMD_MASK = 0x0300
CMD_NOP = 0x0000
CMD_READ = 0x0100
CMD_WRITE = 0x0200
READ_ERROR = 0x2000
COMMAND_ERROR = 0x4000

#: PHY_OFFSET pin: the evaluation board ties it low (TMC8460 §3.3, §3.4.2)
PHY_OFFSET = 0
N_PHY_PORTS = 2  # ports 0 and 1 have a PHY; 2 and 3 are not implemented (§5.7)

#: IEEE 802.3 clause 22 registers of the modelled PHY after reset (IP101GA): basic control
#: (100 Mbit/s, autonegotiation, full duplex), basic status without link, PHY identifier
#: (OUI 0x0090C3), autonegotiation advertisement (100/10 Mbit/s full/half, IEEE 802.3).
PHY_RESET = {0: 0x3100, 1: 0x7849, 2: 0x0243, 3: 0x0C54, 4: 0x01E1}
#: basic status with a link: + link status (1.2) and autonegotiation complete (1.5)
STATUS_LINK = 0x0024
#: link partner ability with a link (acknowledge, 100/10 Mbit/s full/half, IEEE 802.3)
PARTNER_LINK = 0x41E1
#: registers a write does not change: status, identifier, link partner, expansion
READ_ONLY = frozenset({1, 2, 3, 5, 6})


class MiiUnit:
    """The ESC side of the MII management interface and the PHYs on its bus, and the hooks
    of its registers 0x0510-0x051B (the ESC ``esc`` gives the frame and the write range)."""

    __slots__ = ("esc", "mem", "phys", "we_frame")

    def __init__(self, esc: Esc) -> None:
        self.esc = esc
        self.mem = esc.mem
        #: per port: 32 PHY registers (the PHYs are separate chips: an ESC reset keeps them)
        self.phys = [self._phy_reset() for _ in range(N_PHY_PORTS)]
        self.we_frame = -1

    @staticmethod
    def _phy_reset() -> list[int]:
        regs32 = [0] * 32
        for r, v in PHY_RESET.items():
            regs32[r] = v
        return regs32

    def reset(self) -> None:
        """ESC reset: the interface idle, port 0's PHY address shown. Ref: Table 67."""
        self.we_frame = -1
        self.show_address()

    # -- helpers --------------------------------------------------------------------

    def _control(self) -> int:
        m = self.mem
        return m[regs.MII_CONTROL] | (m[regs.MII_CONTROL + 1] << 8)

    def _set_control(self, v: int) -> None:
        self.mem[regs.MII_CONTROL] = v & 0xFF
        self.mem[regs.MII_CONTROL + 1] = (v >> 8) & 0xFF

    def pdi_owns(self) -> bool:
        """PDI controls the interface if 0x0517.0 = 1. Ref: §5.46 Table 72."""
        return bool(self.mem[regs.MII_PDI_ACCESS] & 0x01)

    def show_address(self) -> None:
        """0x0510[7:3]: the PHY address of port 0, or of the port 0x0512[4:0] selects
        when 0x0512.7 = 1. Ref: Table 67 bits 7:3, Table 68 bit 7."""
        sel = self.mem[regs.MII_PHY_ADDRESS]
        addr = PHY_OFFSET + ((sel & 0x1F) if sel & 0x80 else 0)
        c = (self._control() & ~PORT0_ADDR_MASK) | ((addr << PORT0_ADDR_SHIFT) & PORT0_ADDR_MASK)
        self._set_control(c)

    def ownership_changed(self) -> None:
        """0x0510.0 is always 1 while the PDI has MI control, and starts cleared when ECAT
        gets it back. Ref: TMC8460 §5.46 Table 67 bit 0, Table 72."""
        if self.pdi_owns():
            self.mem[regs.MII_CONTROL] |= WRITE_ENABLE
        else:
            self.mem[regs.MII_CONTROL] &= ~WRITE_ENABLE & 0xFF
            self.we_frame = -1

    def refresh_write_enable(self, frame_no: int) -> None:
        """ECAT's write enable self-clears at the SOF of the next frame. Ref: Table 67 *."""
        if self.we_frame != frame_no and not self.pdi_owns():
            self.mem[regs.MII_CONTROL] &= ~WRITE_ENABLE & 0xFF

    # -- the command machine ------------------------------------------------------------

    def control_written(self, old: int, wrote_cmd: bool, frame_no: int, pdi: bool) -> None:
        """A write of 0x0510:0x0511 by the side that owns the interface: clears the read
        error, runs the command written to bits 9:8. Ref: TMC8460 §5.46 Table 67."""
        new = self._control()
        if pdi:
            write_enabled = True  # "always 1 if PDI has MI control"
        else:
            if new & WRITE_ENABLE:
                self.we_frame = frame_no
            write_enabled = self.we_frame == frame_no
        st = (old & ~(CMD_MASK | READ_ERROR | WRITE_ENABLE)) | (new & WRITE_ENABLE)
        if wrote_cmd:
            cmd = new & CMD_MASK
            if cmd == CMD_NOP:
                st &= ~COMMAND_ERROR
            elif cmd == CMD_READ:
                st &= ~COMMAND_ERROR
                if not self._read():
                    st |= READ_ERROR
            elif cmd == CMD_WRITE and write_enabled:
                st &= ~COMMAND_ERROR
                self._write()
            else:  # invalid command, or a write without write enable
                st |= COMMAND_ERROR
        self._set_control(st)

    def _target(self) -> tuple[list[int] | None, int]:
        m = self.mem
        port = (m[regs.MII_PHY_ADDRESS] & 0x1F) - PHY_OFFSET
        phy = self.phys[port] if 0 <= port < N_PHY_PORTS else None
        return phy, m[regs.MII_PHY_REGISTER] & 0x1F

    def _read(self) -> bool:
        """Read a PHY register into 0x0514; False (read error) if no PHY answers: MDIO's
        pull-up then reads all ones."""
        phy, reg = self._target()
        m = self.mem
        value = 0xFFFF if phy is None else phy[reg]
        m[regs.MII_PHY_DATA] = value & 0xFF
        m[regs.MII_PHY_DATA + 1] = value >> 8
        return phy is not None

    def _write(self) -> None:
        phy, reg = self._target()
        if phy is None or reg in READ_ONLY:
            return
        m = self.mem
        value = m[regs.MII_PHY_DATA] | (m[regs.MII_PHY_DATA + 1] << 8)
        if reg == 0 and value & 0x8000:  # software reset, self-clearing
            phy[:] = self._phy_reset()
            return
        phy[reg] = value

    def set_link(self, port: int, up: bool) -> None:
        """The PHY of ``port`` sees its link come or go (basic status 1.2/1.5, partner)."""
        if not 0 <= port < N_PHY_PORTS:
            return
        phy = self.phys[port]
        if up:
            phy[1] |= STATUS_LINK
            phy[5] = PARTNER_LINK
            phy[6] = 0x0001  # link partner autonegotiation able
        else:
            phy[1] &= ~STATUS_LINK & 0xFFFF
            phy[5] = 0
            phy[6] = 0

    # -- register hooks (ecatsim/esc/dispatch.py: side_effect mii.<name>) ----------------

    def _wrote_cmd(self, ra: int) -> bool:
        """The write in progress wrote 0x0511 (the command bits 9:8)."""
        return self.esc.wr_s <= ra + 1 < self.esc.wr_e

    def _ew_control(self, ra: int, rs: int, old: bytes) -> None:
        """ECAT writes 0x0510 only while it has MI control. Ref: TMC8460 §5.46 Table 67
        r/(w)."""
        if self.pdi_owns():
            self.mem[ra : ra + rs] = old
            return
        o = old[0] | (old[1] << 8)
        self.control_written(o, self._wrote_cmd(ra), self.esc.ctx.frame_no, False)

    def _pw_control(self, ra: int, rs: int, old: bytes) -> None:
        """The PDI writes commands only while it has MI control. Ref: TMC8460 §5.46
        Table 67 r/(w)."""
        if not self.pdi_owns():
            self.mem[ra : ra + rs] = old
            return
        o = old[0] | (old[1] << 8)
        self.control_written(o, self._wrote_cmd(ra), self.esc.ctx.frame_no, True)

    def _er_control(self, ra: int, rs: int) -> None:
        """Ref: TMC8460 §5.46 Table 67 note * (write enable self-clears at the next SOF)."""
        self.refresh_write_enable(self.esc.ctx.frame_no)

    def _pr_control(self, ra: int, rs: int) -> None:
        """Ref: TMC8460 §5.46 Table 67 note *."""
        self.refresh_write_enable(self.esc.ctx.frame_no)

    def _ew_phy(self, ra: int, rs: int, old: bytes) -> None:
        """PHY address, register and data: written by the side with MI control.
        Ref: TMC8460 §5.46 Tables 68-70 r/(w)."""
        if self.pdi_owns():
            self.mem[ra : ra + rs] = old
        elif ra == regs.MII_PHY_ADDRESS:
            self.show_address()

    def _pw_phy(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.46 Tables 68-70 r/(w)."""
        if not self.pdi_owns():
            self.mem[ra : ra + rs] = old
        elif ra == regs.MII_PHY_ADDRESS:
            self.show_address()

    def _ew_ecat_access(self, ra: int, rs: int, old: bytes) -> None:
        """ECAT claims or frees MI access only while 0x0517.0 = 0. Ref: TMC8460 §5.46
        Table 71 note."""
        if self.mem[regs.MII_PDI_ACCESS] & 0x01:
            self.mem[ra] = old[0]

    def _ew_pdi_access(self, ra: int, rs: int, old: bytes) -> None:
        """Bit 1 (force PDI access state) resets 0x0517.0. Ref: TMC8460 §5.46 Table 72."""
        if self.mem[ra] & 0x02:
            self.mem[ra] &= 0xFE
        self.ownership_changed()

    def _pw_pdi_access(self, ra: int, rs: int, old: bytes) -> None:
        """The PDI takes MI access only if ECAT allows it (0x0516.0 = 0, 0x0517.1 = 0) and
        the EEPROM is loaded (0x0110.0 = 1); it can always give it back. Ref: TMC8460
        §5.46 Table 72."""
        m = self.mem
        take = m[ra] & 0x01 and not old[0] & 0x01
        if take and (
            m[regs.MII_ECAT_ACCESS] & 0x01 or old[0] & 0x02 or not m[regs.DL_STATUS] & 0x01
        ):
            m[ra] = old[0]
        self.ownership_changed()

    def _ew_port_status(self, ra: int, rs: int, old: bytes) -> None:
        """Writing any PHY port status register clears bits 3 and 5 of all four (by the
        side with MI control). Ref: TMC8460 §5.46 Table 73."""
        if not self.pdi_owns():
            self._clear_port_status()

    def _pw_port_status(self, ra: int, rs: int, old: bytes) -> None:
        """Ref: TMC8460 §5.46 Table 73 r/(w/clr)."""
        if self.pdi_owns():
            self._clear_port_status()

    def _clear_port_status(self) -> None:
        m = self.mem
        for a in range(regs.PHY_PORT_STATUS, regs.PHY_PORT_STATUS + 4):
            m[a] &= ~0x28 & 0xFF
