"""CoE Emergency: error code, error register 0x1001, 0x603F and the 0x1003 history.

Ref: ETG.1000.6 §5.6.4 (emergency: CoE service 1, 8 bytes: error code u16, error
register u8, 5 manufacturer bytes); CiA 301 §7.2.7 (EMCY), §7.5.2.2 (0x1001), §7.5.2.4
(0x1003); CiA 402 (0x603F error code).
"""

from __future__ import annotations

import struct

from ecatsim.slave.mailbox import MailboxEngine
from ecatsim.slave.od import ObjectDictionary
from ecatsim.wire.mailbox import CoeService, MbxType

HISTORY = 0x1003
ERROR_REGISTER = 0x1001
ERROR_CODE_402 = 0x603F

# 0x1001 bits. Ref: TMC8670 §4.1.2 Table 9.
REG_GENERIC = 0x01
REG_CURRENT = 0x02
REG_VOLTAGE = 0x04
REG_TEMPERATURE = 0x08
REG_COMMUNICATION = 0x10
REG_PROFILE = 0x20
REG_MANUFACTURER = 0x80


class Emergency:
    """Sends EMCY messages and keeps the error objects in the OD consistent."""

    def __init__(self, mbx: MailboxEngine, od: ObjectDictionary) -> None:
        self.mbx = mbx
        self.od = od
        self.sent = 0

    def raise_error(self, code: int, register_bits: int, data: bytes = b"") -> None:
        """Record and send an error. Ref: CiA 301 §7.2.7.1; ETG.1000.6 §5.6.4."""
        od = self.od
        reg = REG_GENERIC | register_bits
        if ERROR_REGISTER in od:
            reg |= int(od.value(ERROR_REGISTER))
            od.set(ERROR_REGISTER, 0, reg & 0xFF)
        if ERROR_CODE_402 in od:
            od.set(ERROR_CODE_402, 0, code)
        if HISTORY in od:
            h = od[HISTORY]
            n = int(h.entries[0].value)
            depth = h.max_sub
            for s in range(min(n + 1, depth), 1, -1):
                h.entries[s].value = h.entries[s - 1].value
            if depth:
                h.entries[1].value = code | (
                    int.from_bytes(data[:2].ljust(2, b"\0"), "little") << 16
                )
                h.entries[0].value = min(n + 1, depth)
        self._send(code, reg & 0xFF, data)

    def clear(self) -> None:
        """Error reset: EMCY 0x0000 'error reset or no error'. Ref: CiA 301 Table 21."""
        if ERROR_REGISTER in self.od:
            self.od.set(ERROR_REGISTER, 0, 0)
        if ERROR_CODE_402 in self.od:
            self.od.set(ERROR_CODE_402, 0, 0)
        self._send(0x0000, 0, b"")

    def _send(self, code: int, reg: int, data: bytes) -> None:
        coe = struct.pack("<H", int(CoeService.EMERGENCY) << 12)
        self.mbx.post(MbxType.COE, coe + struct.pack("<HB", code, reg) + data[:5].ljust(5, b"\0"))
        self.sent += 1
