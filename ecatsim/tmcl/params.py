"""The TMCM-1311's axis parameters and global parameters as data.

Each entry: number, name, range, factory default, access and the manual section that
defines it. Access letters as in the manual (§6): R readable (GAP/GGP), W writable
(SAP/AAP, SGP/AGP), E stored in the configuration EEPROM (STAP/RSAP, STGP/RSGP) and restored
at power-up. Defaults the manual does not give are chosen in docs/decisions.md (T6).

Ref: TMCM-1311 TMCL firmware manual §6 (axis parameters), §7 (stallGuard2), §8 (closed
loop), §9 (reference search), §10.1-10.4 (global parameter banks 0-3).
"""

from __future__ import annotations

from dataclasses import dataclass

I32_MIN, I32_MAX = -(1 << 31), (1 << 31) - 1
U32_MAX = (1 << 32) - 1
VEL_MAX = 327_679_999
#: ROR/ROL and the search speeds (§5.7.1)
ROR_MIN, ROR_MAX = -268_435_455, 268_435_454


@dataclass(frozen=True, slots=True)
class Param:
    """One axis or global parameter."""

    number: int
    name: str
    lo: int
    hi: int
    default: int
    access: str
    ref: str
    #: the only values allowed, where the range has holes
    choices: tuple[int, ...] | None = None

    @property
    def readable(self) -> bool:
        return "R" in self.access

    @property
    def writable(self) -> bool:
        return "W" in self.access

    @property
    def storable(self) -> bool:
        return "E" in self.access

    @property
    def unsigned(self) -> bool:
        """The value field carries 0..2^32-1 (the range reaches past 2^31-1)."""
        return self.hi > I32_MAX

    def valid(self, value: int) -> bool:
        if self.choices is not None:
            return value in self.choices
        return self.lo <= value <= self.hi


def _p(n: int, name: str, lo: int, hi: int, default: int, access: str, ref: str) -> Param:
    return Param(n, name, lo, hi, default, access, ref)


_SEARCH_MODES = (*range(1, 9), *range(129, 137))
_ENCODER_MODES = tuple(m for m in range(0, 29) if m & ~0b11100 == 0)

AXIS: dict[int, Param] = {
    p.number: p
    for p in (
        _p(0, "target position", I32_MIN, I32_MAX, 0, "RW", "§6"),
        _p(1, "actual position", I32_MIN, I32_MAX, 0, "RW", "§6"),
        _p(2, "target speed", -327_678_000, VEL_MAX, 0, "RW", "§6"),
        _p(3, "actual speed", -327_678_000, VEL_MAX, 0, "RW", "§6"),
        _p(4, "maximum positioning speed", 0, VEL_MAX, 51_200, "RWE", "§6"),
        _p(5, "maximum acceleration", 1, 24_999_998, 51_200, "RWE", "§6"),
        _p(6, "absolute max. current", 0, 255, 128, "RWE", "§6"),
        _p(7, "standby current", 0, 255, 8, "RWE", "§6"),
        _p(8, "target pos. reached", 0, 1, 0, "R", "§6"),
        _p(9, "ref. switch status", 0, 1, 0, "R", "§6"),
        _p(10, "right limit switch status", 0, 1, 0, "R", "§6"),
        _p(11, "left limit switch status", 0, 1, 0, "R", "§6"),
        _p(12, "right limit switch disable", 0, 1, 0, "RWE", "§6"),
        _p(13, "left limit switch disable", 0, 1, 0, "RWE", "§6"),
        _p(14, "CL torque mode target current", -3000, 3000, 0, "RW", "§6, §8.7"),
        _p(15, "maximum possible current", 0, 3000, 0, "R", "§6"),
        _p(16, "CL velocity reached", 0, 1, 0, "R", "§6, §8.6"),
        _p(17, "CL velocity reached window", 0, 268_435_454, 1000, "RW", "§6, §8.6"),
        _p(18, "status word", 0, 0x3FFF, 0, "R", "§6"),
        _p(19, "CL torque mode actual current", -3000, 3000, 0, "RW", "§8.7"),
        _p(20, "CL torque mode slope", 0, I32_MAX, 100_000, "RW", "§6, §8.7"),
        _p(25, "thermal winding time constant", 0, U32_MAX, 4500, "RWE", "§6"),
        _p(26, "I2t limit", 0, U32_MAX, 500_000, "RWE", "§6"),
        _p(27, "I2t sum", 0, U32_MAX, 0, "R", "§6"),
        _p(28, "I2t exceed counter", 0, U32_MAX, 0, "RWE", "§6"),
        _p(29, "clear I2t exceeded flag", I32_MIN, U32_MAX, 0, "W", "§6"),
        _p(108, "CL field weakening minimum velocity", 0, VEL_MAX, 200_000, "RW", "§8.9"),
        _p(109, "CL field weakening maximum velocity", 0, VEL_MAX, 400_000, "RW", "§8.9"),
        _p(112, "CL encoder offset", I32_MIN, I32_MAX, 0, "RWE", "§6, §8.3"),
        _p(113, "CL current scale minimum", 0, 255, 15, "RW", "§8.8"),
        _p(114, "CL current scale maximum", 0, 255, 255, "RW", "§8.8"),
        _p(115, "CL current scale input select", 0, 1, 1, "RW", "§8.8"),
        _p(116, "CL current scale lower error limit", 0, I32_MAX, 0, "RW", "§8.8"),
        _p(117, "CL current scale upper error limit", 0, I32_MAX, 255, "RW", "§8.8"),
        _p(118, "CL current scale increment value", 0, 255, 1, "RW", "§8.8"),
        _p(119, "CL current scale decrement value", 0, 255, 1, "RW", "§8.8"),
        _p(120, "CL current scale increment timeout", 0, 65535, 0, "RW", "§8.8"),
        _p(121, "CL current scale decrement timeout", 0, 65535, 0, "RW", "§8.8"),
        _p(122, "CL current scale enable", 0, 1, 1, "RW", "§8.8"),
        _p(123, "CL actual current scale factor", 0, 255, 0, "R", "§8.8"),
        _p(124, "CL correction velocity proportional factor", 0, 65535, 1000, "RW", "§8.4"),
        _p(125, "CL max. following error", 0, 268_435_454, 0, "RW", "§8.4"),
        _p(126, "CL max. correction velocity", 0, VEL_MAX, 0, "RW", "§8.4"),
        _p(127, "relative positioning option", 0, 2, 0, "RW", "§8.4"),
        _p(128, "ramp mode", 0, 2, 0, "RW", "§6, §8.1"),
        _p(129, "closed loop operation", 0, 1, 0, "RW", "§6, §8.1"),
        _p(130, "start/stop velocity", 0, VEL_MAX, 0, "RWE", "§6, §8.4"),
        _p(131, "measured speed", I32_MIN, I32_MAX, 0, "R", "§6"),
        _p(132, "encoder initialization", 0, 1, 0, "RW", "§6"),
        _p(133, "CL init flag", 0, 1, 0, "R", "§6, §8.1"),
        _p(134, "CL position reached window", 0, 255, 50, "RW", "§8.5"),
        _p(135, "CL position reached time", 0, 131_072, 100, "RW", "§8.5"),
        _p(136, "CL standstill position error gain", 10, 50, 10, "RW", "§8.5"),
        _p(137, "CL standstill position error dampening", 0, 65535, 0, "RW", "§8.5"),
        _p(138, "CL standstill position error limit", 0, 268_435_454, 255, "RW", "§8.5"),
        _p(140, "microstep resolution", 0, 8, 8, "RWE", "§6"),
        _p(141, "CL torque mode start/stop current", 0, 3000, 0, "RW", "§8.7"),
        _p(149, "soft stop flag", 0, 1, 1, "RW", "§9"),
        _p(150, "motor current", 0, I32_MAX, 0, "R", "§8.7"),
        _p(151, "current phase A", -4200, 4200, 0, "R", "§6"),
        _p(152, "current phase B", -4200, 4200, 0, "R", "§6"),
        _p(153, "supply voltage", 0, 65535, 240, "R", "§6"),
        _p(154, "DC current", 0, 65535, 0, "R", "§6"),
        _p(155, "module temperature", -50, 200, 30, "R", "§6"),
        _p(162, "chopper blank time", 0, 3, 2, "RW", "§6"),
        _p(163, "chopper mode", 0, 1, 0, "RW", "§6"),
        _p(164, "chopper hysteresis decrement", 0, 3, 0, "RW", "§6"),
        _p(165, "chopper hysteresis end", -3, 12, 2, "RW", "§6"),
        _p(166, "chopper hysteresis start", 0, 8, 3, "RW", "§6"),
        Param(167, "chopper off time", 0, 15, 5, "RW", "§6", (0, *range(2, 16))),
        _p(168, "smartEnergy current minimum", 0, 1, 0, "RW", "§6"),
        _p(169, "smartEnergy current down step", 0, 3, 0, "RW", "§6"),
        _p(170, "smartEnergy hysteresis", 0, 15, 0, "RW", "§6"),
        _p(171, "smartEnergy current up step", 1, 3, 1, "RW", "§6"),
        _p(172, "smartEnergy hysteresis start", 0, 15, 0, "RW", "§6"),
        _p(173, "stallGuard2 filter enable", 0, 1, 0, "RW", "§6, §7"),
        _p(174, "stallGuard2 threshold", -64, 63, 0, "RW", "§6, §7"),
        _p(175, "slope control high side", 0, 3, 2, "RW", "§6"),
        _p(176, "slope control low side", 0, 3, 2, "RW", "§6"),
        _p(177, "short protection disable", 0, 1, 0, "RW", "§6"),
        _p(178, "short detection timer", 0, 3, 0, "RW", "§6"),
        _p(179, "Vsense", 0, 1, 0, "RW", "§6"),
        _p(180, "smartEnergy actual current", 0, 31, 31, "RW", "§6"),
        _p(181, "stop on stall", 0, VEL_MAX, 0, "RW", "§6, §7"),
        _p(182, "smartEnergy threshold speed", 0, VEL_MAX, 0, "RW", "§6"),
        _p(183, "smartEnergy slow run current", 0, 255, 0, "RW", "§6"),
        Param(193, "ref. search mode", 1, 136, 1, "RWE", "§6, §9", _SEARCH_MODES),
        _p(194, "referencing search speed", 0, VEL_MAX, 51_200, "RWE", "§6, §9"),
        _p(195, "referencing switch speed", 0, VEL_MAX, 12_800, "RWE", "§6, §9"),
        _p(196, "end switch distance", 0, I32_MAX, 0, "R", "§6, §9"),
        _p(198, "clear on null", 0, 1, 0, "RW", "§6"),
        _p(200, "boost current", 0, 255, 0, "RWE", "§6"),
        Param(201, "encoder mode", 0, 28, 0, "RWE", "§6, §8.3", _ENCODER_MODES),
        _p(202, "motor resolution", 0, 400, 200, "RW", "§6, §8.3"),
        _p(204, "freewheeling", 0, 65535, 0, "RWE", "§6"),
        _p(206, "actual load value", 0, 1023, 0, "R", "§6, §7"),
        _p(207, "max encoder deviation error flag", 0, 1, 0, "R", "§6, §8.1"),
        _p(208, "driver error flags", 0, 255, 0, "R", "§6"),
        _p(209, "encoder counter", I32_MIN, I32_MAX, 0, "RW", "§6"),
        _p(210, "encoder resolution", 0, 65535, 40_000, "RW", "§6, §8.3"),
        _p(212, "max. encoder deviation", I32_MIN, I32_MAX, 0, "RWE", "§6, §8.1"),
        _p(214, "power down delay", 1, 65535, 200, "RWE", "§6"),
        _p(230, "gamma", 0, 255, 0, "R", "§8.9"),
        _p(233, "virtual actual position", I32_MIN, I32_MAX, 0, "R", "§6, §8.10"),
        _p(236, "CL actual target current scale factor", 0, 255, 0, "R", "§8.8"),
        _p(237, "position error", I32_MIN, I32_MAX, 0, "R", "§6, §8.10"),
        _p(254, "step/dir mode", 0, 5, 0, "RWE", "§6"),
    )
}

#: bank 0 (§10.1): the module's configuration
BANK0: dict[int, Param] = {
    p.number: p
    for p in (
        _p(64, "EEPROM magic", 0, 255, 0xE4, "RWE", "§10.1"),
        _p(65, "RS485 baud rate", 0, 11, 0, "RWE", "§10.1"),
        _p(66, "serial address", 0, 255, 1, "RWE", "§10.1"),
        Param(67, "ASCII mode", 0, 49, 0, "RWE", "§4.4.4, §10.1", (0, 1, 16, 17, 32, 33)),
        _p(68, "serial heartbeat", 0, 65535, 0, "RWE", "§10.1"),
        _p(69, "CAN bit rate", 2, 8, 8, "RWE", "§10.1"),
        _p(70, "CAN reply ID", 0, 0x7FF, 2, "RWE", "§10.1"),
        _p(71, "CAN ID", 0, 0x7FF, 1, "RWE", "§10.1"),
        Param(73, "configuration EEPROM lock flag", 0, 4321, 0, "RWE", "§10.1", (1234, 4321)),
        _p(75, "telegram pause time", 0, 255, 0, "RWE", "§10.1"),
        _p(76, "serial host address", 0, 255, 2, "RWE", "§10.1"),
        _p(77, "auto start mode", 0, 1, 0, "RWE", "§10.1"),
        _p(79, "end switch polarity", 0, 1, 0, "RWE", "§10.1"),
        _p(81, "TMCL code protection", 0, 3, 0, "RWE", "§10.1"),
        _p(83, "CAN secondary address", 0, 0x7FF, 0, "RWE", "§10.1"),
        _p(84, "coordinate storage", 0, 1, 0, "RWE", "§10.1"),
        _p(85, "do not restore user variables", 0, 1, 0, "RWE", "§10.1"),
        _p(88, "interface selection", 0, 1, 1, "RWE", "§3.1, §10.1"),
        _p(128, "TMCL application status", 0, 3, 0, "R", "§10.1"),
        _p(129, "download mode", 0, 1, 0, "R", "§10.1"),
        _p(130, "TMCL program counter", 0, I32_MAX, 0, "R", "§10.1"),
        _p(132, "tick timer", I32_MIN, U32_MAX, 0, "RW", "§10.1"),
        _p(133, "random number", 0, I32_MAX, 0, "R", "§10.1"),
    )
}

#: bank 0 parameters 64-127 live in the EEPROM only: SGP stores them at once (§10.1)
EEPROM_ONLY = range(64, 128)

#: bank 2 (§10.3): 256 user variables, #0-#55 storable
USER_VARS = 256
USER_VARS_STORED = 56

#: bank 3 (§10.4): interrupt configuration
BANK3: dict[int, Param] = {
    p.number: p
    for p in (
        _p(0, "timer 0 period", 0, U32_MAX, 0, "RW", "§10.4"),
        _p(1, "timer 1 period", 0, U32_MAX, 0, "RW", "§10.4"),
        _p(2, "timer 2 period", 0, U32_MAX, 0, "RW", "§10.4"),
        _p(27, "stop left 0 trigger transition", 0, 3, 0, "RW", "§10.4"),
        _p(28, "stop right 0 trigger transition", 0, 3, 0, "RW", "§10.4"),
        *(_p(39 + i, f"input {i} edge type", 0, 3, 0, "RW", "§10.4") for i in range(8)),
    )
}


def user_var(number: int) -> Param:
    """Bank 2 variable ``number`` (§10.3)."""
    access = "RWE" if number < USER_VARS_STORED else "RW"
    return Param(number, f"user variable #{number}", I32_MIN, U32_MAX, 0, access, "§10.3")


def global_param(bank: int, number: int) -> Param | None:
    """The global parameter, or None where the bank has no such number (bank 1 has none)."""
    if bank == 0:
        return BANK0.get(number)
    if bank == 2:
        return user_var(number) if 0 <= number < USER_VARS else None
    if bank == 3:
        return BANK3.get(number)
    return None


def norm(p: Param, value: int) -> int:
    """The value field (signed 32-bit) as the parameter's own number (unsigned where its
    range is)."""
    return value & U32_MAX if p.unsigned and p.lo >= 0 else value
