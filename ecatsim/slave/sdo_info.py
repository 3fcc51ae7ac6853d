"""SDO Information service: OD list, object description, entry description, fragmented.

Ref: ETG.1000.6 §5.6.3 (SDO Information), Tables 44-51.
"""

from __future__ import annotations

import struct

from ecatsim.slave.od import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ObjectDictionary, SdoAbort
from ecatsim.wire.mailbox import CoeService

OP_OD_LIST_REQ = 1
OP_OD_LIST_RESP = 2
OP_OBJ_DESC_REQ = 3
OP_OBJ_DESC_RESP = 4
OP_ENTRY_DESC_REQ = 5
OP_ENTRY_DESC_RESP = 6
OP_ERROR = 7
INCOMPLETE = 0x80

# Object access bits of the entry description. Ref: ETG.1000.6 Table 50.
ACC_READ_ALL = 0x0007
ACC_WRITE_ALL = 0x0038
ACC_WRITE_PREOP = 0x0008
ACC_RXPDO = 0x0040
ACC_TXPDO = 0x0080


def _write_bits(states: tuple[int, ...]) -> int:
    """Access bits 3-5 (write in PREOP, SAFEOP, OP) of the states a write is allowed in."""
    bits = 0
    for st, bit in ((2, ACC_WRITE_PREOP), (4, ACC_WRITE_PREOP << 1), (8, ACC_WRITE_PREOP << 2)):
        if st in states:
            bits |= bit
    return bits


def _hdr(opcode: int, incomplete: bool, fragments_left: int) -> bytes:
    coe = (int(CoeService.SDO_INFO) << 12).to_bytes(2, "little")
    return (
        coe
        + bytes([opcode | (INCOMPLETE if incomplete else 0), 0])
        + struct.pack("<H", fragments_left)
    )


class SdoInfo:
    """Answers SDO Information requests from the object dictionary."""

    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od

    def handle(self, data: bytes, max_body: int) -> list[bytes]:
        """One request (CoE header included) -> reply fragments (CoE header included)."""
        if len(data) < 6:
            return [self._error(0x0504_0001)]
        opcode = data[2] & 0x7F
        body = data[6:]
        try:
            if opcode == OP_OD_LIST_REQ:
                return self._fragment(OP_OD_LIST_RESP, self._od_list(body), max_body)
            if opcode == OP_OBJ_DESC_REQ:
                return [_hdr(OP_OBJ_DESC_RESP, False, 0) + self._obj_desc(body)]
            if opcode == OP_ENTRY_DESC_REQ:
                return [_hdr(OP_ENTRY_DESC_RESP, False, 0) + self._entry_desc(body)]
        except SdoAbort as exc:
            return [self._error(exc.code)]
        except struct.error:
            return [self._error(0x0504_0001)]
        return [self._error(0x0504_0001)]

    @staticmethod
    def _error(code: int) -> bytes:
        return _hdr(OP_ERROR, False, 0) + struct.pack("<I", code)

    @staticmethod
    def _fragment(opcode: int, payload: bytes, max_body: int) -> list[bytes]:
        """Split a long reply into fragments that fit the mailbox; the list type is only in
        the first. Ref: ETG.1000.6 §5.6.3.3 (fragments left, incomplete flag)."""
        room = max(2, (max_body - 6) & ~1)
        chunks = [payload[i : i + room] for i in range(0, len(payload), room)] or [b""]
        out = []
        for i, c in enumerate(chunks):
            left = len(chunks) - 1 - i
            out.append(_hdr(opcode, left > 0, left) + c)
        return out

    def _od_list(self, body: bytes) -> bytes:
        """List type 0: counts; 1 all; 2 RxPDO mappable; 3 TxPDO mappable; 4 backup; 5 startup.
        Ref: ETG.1000.6 Table 46."""
        (list_type,) = struct.unpack_from("<H", body)
        objs = list(self.od.objects.values())
        rx = [o.index for o in objs if any(e.pdo and e.access != "ro" for e in o.entries.values())]
        tx = [o.index for o in objs if any(e.pdo for e in o.entries.values())]
        lists = {1: [o.index for o in objs], 2: rx, 3: tx, 4: [], 5: []}
        if list_type == 0:
            return struct.pack("<H5H", 0, *(len(lists[k]) for k in range(1, 6)))
        if list_type not in lists:
            raise SdoAbort(0x0800_0000)
        return struct.pack("<H", list_type) + b"".join(
            struct.pack("<H", i) for i in lists[list_type]
        )

    def _obj_desc(self, body: bytes) -> bytes:
        """Index, data type, max subindex, object code, name. Ref: ETG.1000.6 Table 48."""
        (index,) = struct.unpack_from("<H", body)
        if index not in self.od:
            raise SdoAbort(ABORT_NO_OBJECT)
        o = self.od[index]
        return struct.pack("<HHBB", index, o.data_type, o.max_sub, int(o.code)) + o.name.encode(
            "latin-1", "replace"
        )

    def _entry_desc(self, body: bytes) -> bytes:
        """Entry: data type, bit length, access, name. Ref: ETG.1000.6 Tables 49, 50."""
        index, sub, _value_info = struct.unpack_from("<HBB", body)
        if index not in self.od:
            raise SdoAbort(ABORT_NO_OBJECT)
        e = self.od[index].entries.get(sub)
        if e is None:
            raise SdoAbort(ABORT_NO_SUBINDEX)
        acc = 0 if e.access == "wo" else ACC_READ_ALL
        if e.access != "ro":
            acc |= _write_bits(e.write_states) if e.write_states else ACC_WRITE_ALL
        if e.pdo:
            acc |= ACC_RXPDO if e.access != "ro" else 0
            acc |= ACC_TXPDO
        bits = e.bits if not e.is_string else 8 * e.size
        return struct.pack("<HBBHHH", index, sub, 0, e.type_code, bits, acc) + e.name.encode(
            "latin-1", "replace"
        )
