"""The MFCIO register set as data: number, unit, direction, size and where each register
lives (configuration byte, memory block offset, MFC CTRL SPI address).

Ref: TMC8460 §6.2 Table 133 (register overview), §5.53.1 Tables 129/130 (MB0 and its
padding), §5.53.2 Tables 131/132 (MB1 and its padding), §6.3 Table 134 (EEPROM map),
§3.6 (MFC CTRL SPI addressing), §6.15 Table 156 (register 44).
"""

from __future__ import annotations

from dataclasses import dataclass

#: memory block 0: registers the master writes. Ref: TMC8460 §5.53.1 Table 129.
MB0_START = 0x4000
MB0_SIZE = 0x60
#: memory block 1: registers the master reads. Ref: TMC8460 §5.53.2 Table 131.
MB1_START = 0x4800
MB1_SIZE = 0x24
#: the configuration bytes in the ESC parameter RAM. Ref: TMC8460 §5.47 Table 74.
CONFIG_START = 0x0580
#: registers 0..43 have a configuration byte; 44 (AL_STATE_OVERRIDE) has none
N_CONFIGURED = 44
#: where the configuration vector starts in the EEPROM (bytes). Ref: TMC8460 §6.3 Table 134.
EEPROM_CONFIG_BYTE = 0x0084


@dataclass(frozen=True, slots=True)
class MfcReg:
    """One MFCIO register (TMC8460 §6.2 Table 133)."""

    num: int
    name: str
    unit: str
    #: True: written by the master (or the MFC CTRL SPI); False: read-only
    writable: bool
    #: data size in bytes
    size: int
    #: PDRAM address in MB0 (writable) or MB1 (readable); None for register 44
    mb: int | None
    #: the bits the unit implements (the rest read 0)
    mask: int

    @property
    def config_addr(self) -> int:
        """ESC parameter RAM address of the configuration byte (0x0580 + number)."""
        return CONFIG_START + self.num

    @property
    def eeprom_addr(self) -> int:
        """EEPROM byte address of the configuration byte (0x0084 + number)."""
        return EEPROM_CONFIG_BYTE + self.num

    def spi_addr(self, byte: int = 0) -> int:
        """MFC CTRL SPI address: register number << 4 | byte. Ref: TMC8460 §3.6."""
        return (self.num << 4) | byte


def _r(num: int, name: str, unit: str, rw: str, size: int, mb: int | None, mask: int) -> MfcReg:
    return MfcReg(num, name, unit, rw == "W", size, mb, mask)


_M16 = 0xFFFF
_M32 = 0xFFFFFFFF
_M64 = (1 << 64) - 1

#: Table 133, row by row; masks from the units' register tables (§6.6.2 Table 138,
#: §6.7.2 Table 141, §6.8 Table 144, §6.9 Table 147, §6.10.1 Table 150, §6.11.2
#: Table 151, §6.12 Table 154, §6.15 Table 156).
REGISTERS: tuple[MfcReg, ...] = (
    _r(0, "ENC_MODE", "encoder", "W", 2, 0x4000, 0x85FF),
    _r(1, "ENC_STATUS", "encoder", "R", 1, 0x4800, 0x01),
    _r(2, "ENC_X_W", "encoder", "W", 4, 0x4004, _M32),
    _r(3, "ENC_X", "encoder", "R", 4, 0x4804, _M32),
    _r(4, "ENC_CONST", "encoder", "W", 4, 0x4008, _M32),
    _r(5, "ENC_LATCH", "encoder", "R", 4, 0x4808, _M32),
    _r(6, "SPI_RX_DATA", "spi", "R", 8, 0x480C, _M64),
    _r(7, "SPI_TX_DATA", "spi", "W", 8, 0x400C, _M64),
    _r(8, "SPI_CONF", "spi", "W", 2, 0x4014, 0x877B),
    _r(9, "SPI_STATUS", "spi", "R", 1, 0x4814, 0x01),
    _r(10, "SPI_LENGTH", "spi", "W", 1, 0x4016, 0x3F),
    _r(11, "SPI_TIME", "spi", "W", 1, 0x4017, 0xFF),
    _r(12, "SD_SR", "stepdir", "W", 4, 0x4018, _M32),
    _r(13, "SD_SC", "stepdir", "R", 4, 0x4818, _M32),
    _r(14, "SD_ST", "stepdir", "W", 4, 0x401C, _M32),
    _r(15, "SD_SL", "stepdir", "W", 2, 0x4020, _M16),
    _r(16, "SD_DLY", "stepdir", "W", 2, 0x4022, _M16),
    _r(17, "SD_CFG", "stepdir", "W", 1, 0x4024, 0x3F),
    _r(18, "PWM_MAXCNT", "pwm", "W", 2, 0x4026, 0x0FFF),
    _r(19, "PWM_CHOPMODE", "pwm", "W", 2, 0x4028, 0x0777),
    _r(20, "PWM_ALIGNMENT", "pwm", "W", 1, 0x402A, 0x03),
    _r(21, "PWM_POLARITIES", "pwm", "W", 1, 0x402B, 0x7F),
    _r(22, "PWM_VALUE_0", "pwm", "W", 2, 0x402C, 0x0FFF),
    _r(23, "PWM_VALUE_1", "pwm", "W", 2, 0x402E, 0x0FFF),
    _r(24, "PWM_VALUE_2", "pwm", "W", 2, 0x4030, 0x0FFF),
    _r(25, "PWM_CNTRSHIFT_0", "pwm", "W", 2, 0x4032, 0x0FFF),
    _r(26, "PWM_CNTRSHIFT_1", "pwm", "W", 2, 0x4034, 0x0FFF),
    _r(27, "PWM_CNTRSHIFT_2", "pwm", "W", 2, 0x4036, 0x0FFF),
    _r(28, "PWM_PULSE_A", "pwm", "W", 2, 0x4038, 0x0FFF),
    _r(29, "PWM_PULSE_B", "pwm", "W", 2, 0x403A, 0x0FFF),
    _r(30, "PWM_PULSE_LENGTH", "pwm", "W", 1, 0x403C, 0xFF),
    _r(31, "PWM_BBM_H", "pwm", "W", 1, 0x403D, 0xFF),
    _r(32, "PWM_BBM_L", "pwm", "W", 1, 0x403E, 0xFF),
    _r(33, "GPO_OUT_VAL", "gpio", "W", 2, 0x4040, _M16),
    _r(34, "GPI_IN_VAL", "gpio", "R", 1, 0x481C, 0xFF),
    _r(35, "GPIO_CONFIG", "gpio", "W", 1, 0x4042, 0xFF),
    _r(36, "IRQ_CFG", "irq", "W", 2, 0x4044, 0x80FF),
    _r(37, "IRQ_FLAGS", "irq", "R", 2, 0x481E, 0x80FF),
    _r(38, "WD_TIME", "watchdog", "W", 4, 0x4048, _M32),
    _r(39, "WD_CFG", "watchdog", "W", 1, 0x404C, 0x1F),
    _r(40, "WD_OUT_MASK_POL", "watchdog", "W", 8, 0x4050, _M64),
    _r(41, "WD_OE_POL", "watchdog", "W", 4, 0x4058, _M32),
    _r(42, "WD_IN_MASK_POL", "watchdog", "W", 4, 0x405C, _M32),
    _r(43, "WD_MAX", "watchdog", "R", 4, 0x4820, _M32),
    _r(44, "AL_STATE_OVERRIDE", "override", "W", 1, None, 0x0F),
)

BY_NAME = {r.name: r for r in REGISTERS}
AL_STATE_OVERRIDE = REGISTERS[44]

#: padding in MB0 (written bytes ignored) and MB1 (read as 0x00). Ref: Tables 130, 132.
MB0_PADDING = ((0x4002, 2), (0x4025, 1), (0x403F, 1), (0x4043, 1), (0x4046, 2), (0x404D, 3))
MB1_PADDING = ((0x4801, 3), (0x4815, 3), (0x481D, 1))

#: AL_STATE_OVERRIDE bits: which sub-block's outputs ignore the AL state. Ref: Table 156.
OVERRIDE_SPI = 0x01
OVERRIDE_STEPDIR = 0x02
OVERRIDE_PWM = 0x04
OVERRIDE_GPIO = 0x08


def reg(name: str) -> MfcReg:
    """A register by name (KeyError names the register)."""
    return BY_NAME[name]


def by_spi_addr(addr: int) -> tuple[MfcReg, int] | None:
    """Register and byte number of an MFC CTRL SPI address, or None. Ref: TMC8460 §3.6."""
    num, byte = addr >> 4, addr & 0x0F
    if num >= len(REGISTERS) or byte >= REGISTERS[num].size:
        return None
    return REGISTERS[num], byte
