"""A minimal master on the in-process path: brings one slave of a segment to OP the way a
master does (station address, mailbox SMs, PREOP, PDO sizes from CoE 0x1C12/0x1C13 or the
SII, process data SMs and FMMUs, SAFEOP, OP) and reports the first step that fails.

For ``ecatsim esi check``: frames go over the loopback link to the daemon's own frame
handling (``Daemon.handle_one``), in process.
Ref: ETG.1000.6 §6.4 (AL state machine); ETG.1000.4 §5.6 (mailbox); ETG.1000.6 §5.6.2.4
(SDO upload); ETG.2010 (SII SyncM, PDO categories); TMC8460 §5.48/§5.49 (FMMU/SM registers).
"""

from __future__ import annotations

import struct

from ecatsim.ethercat.daemon import Daemon
from ecatsim.ethercat.segment import Segment
from ecatsim.link.loopback import LoopbackLink
from ecatsim.sii.image import parse_image
from ecatsim.wire import datagram as dg

AL_CONTROL, AL_STATUS, AL_CODE = 0x0120, 0x0130, 0x0134
SM_REG, FMMU_REG = 0x0800, 0x0600
STATION = 0x0010
PREOP, SAFEOP, OP = 2, 4, 8
SM_MBX_OUT, SM_MBX_IN, SM_PD_OUT, SM_PD_IN = 1, 2, 3, 4


class BringUpError(Exception):
    """The step that failed, in one line."""


class MiniMaster:
    """One frame at a time through a segment, with its replies decoded."""

    def __init__(self, seg: Segment) -> None:
        self.seg = seg
        self.counter = 0
        self.link = LoopbackLink()
        self.daemon = Daemon(self.link, seg)
        self.buf = bytearray(2048)

    def exchange(self, datagram: bytes) -> tuple[bytes, int]:
        """One datagram in a frame of its own: its reply data and WKC."""
        self.link.master_send(dg.ethernet_frame([datagram]))
        self.daemon.handle_one(self.buf)
        raw = self.link.master_recv()
        if raw is None:
            raise BringUpError("a frame was lost")
        p = 14 + 2
        length = dg.HEADER.unpack_from(raw, p)[4] & dg.LEN_MASK
        data = bytes(raw[p + 10 : p + 10 + length])
        (wkc,) = struct.unpack_from("<H", raw, p + 10 + length)
        return data, wkc

    def fprd(self, station: int, ado: int, n: int) -> tuple[bytes, int]:
        return self.exchange(dg.build(dg.Cmd.FPRD, station, ado, bytes(n)))

    def fpwr(self, station: int, ado: int, data: bytes) -> int:
        return self.exchange(dg.build(dg.Cmd.FPWR, station, ado, data))[1]

    def apwr(self, pos: int, ado: int, data: bytes) -> int:
        return self.exchange(dg.build(dg.Cmd.APWR, (-pos) & 0xFFFF, ado, data))[1]

    def lrw(self, lad: int, data: bytes) -> tuple[bytes, int]:
        return self.exchange(dg.build_logical(dg.Cmd.LRW, lad, data))

    # ----------------------------------------------------------------- steps

    def state(self, station: int, want: int, what: str) -> None:
        self.fpwr(station, AL_CONTROL, struct.pack("<H", want))
        for _ in range(5):
            data, wkc = self.fprd(station, AL_STATUS, 6)
            st, code = struct.unpack_from("<H2xH", data)
            if wkc == 1 and st & 0x1F == want:
                return
            if st & 0x10:
                raise BringUpError(f"{what} refused: AL status code 0x{code:04X}")
        raise BringUpError(f"{what}: AL status 0x{st:02X}, expected 0x{want:02X}")

    def upload(self, station: int, mbx: tuple[int, int, int, int], index: int, sub: int) -> int:
        """An expedited SDO upload (up to 4 bytes) through the mailbox."""
        out, out_len, inp, in_len = mbx
        self.counter = self.counter % 7 + 1
        body = struct.pack("<HBHBI", 2 << 12, 0x40, index, sub, 0)
        frame = struct.pack("<HHBB", len(body), 0, 0, 0x03 | (self.counter << 4)) + body
        if self.fpwr(station, out, frame.ljust(out_len, b"\x00")) != 1:
            raise BringUpError(f"SDO 0x{index:04X}:{sub}: the mailbox took no request")
        for _ in range(10):
            data, wkc = self.fprd(station, inp, in_len)
            if wkc == 1:
                cmd = data[8]
                if cmd == 0x80:
                    code = struct.unpack_from("<I", data, 12)[0]
                    raise BringUpError(f"SDO 0x{index:04X}:{sub}: abort 0x{code:08X}")
                n = 4 - ((cmd >> 2) & 3) if cmd & 0x01 else 4
                return int.from_bytes(data[12 : 12 + n], "little")
        raise BringUpError(f"SDO 0x{index:04X}:{sub}: no reply")

    def pd_bits(self, station: int, mbx: tuple[int, int, int, int], assign: int) -> int:
        bits = 0
        for k in range(1, self.upload(station, mbx, assign, 0) + 1):
            pdo = self.upload(station, mbx, assign, k)
            for s in range(1, self.upload(station, mbx, pdo, 0) + 1):
                bits += self.upload(station, mbx, pdo, s) & 0xFF
        return bits

    def to_op(self, pos: int) -> str:
        """Bring slave ``pos`` to OP; a one-line summary (BringUpError on failure)."""
        esc = self.seg.escs[pos]
        station = 0x1001 + pos
        if self.apwr(pos, STATION, struct.pack("<H", station)) != 1:
            raise BringUpError("no slave at this position")
        sii = parse_image(bytes(esc.eeprom.image))
        sms = list(sii.sms)
        mbx: tuple[int, int, int, int] | None = None
        by_type: dict[int, tuple[int, tuple[int, int, int, int, int, int]]] = {}
        for i, s in enumerate(sms):
            by_type.setdefault(s[5], (i, s))  # the first SM of each kind
        if SM_MBX_OUT in by_type and SM_MBX_IN in by_type:
            (i0, s0), (i1, s1) = by_type[SM_MBX_OUT], by_type[SM_MBX_IN]
            for i, s in ((i0, s0), (i1, s1)):
                self.fpwr(
                    station, SM_REG + 8 * i, struct.pack("<HHBBBB", s[0], s[1], s[2], 0, 1, 0)
                )
            mbx = (s0[0], s0[1], s1[0], s1[1])
        self.state(station, PREOP, "INIT->PREOP")
        coe = mbx is not None and bool(sii.protocols & 0x04)
        sizes = {}
        for t, assign in ((SM_PD_OUT, 0x1C12), (SM_PD_IN, 0x1C13)):
            if coe:
                assert mbx is not None
                bits = self.pd_bits(station, mbx, assign)
            else:
                kind = "RxPDO" if t == SM_PD_OUT else "TxPDO"
                idx = by_type[t][0] if t in by_type else -1
                bits = sum(
                    b for k, _i, _n, sm, entries in sii.pdos if k == kind and sm == idx
                    for *_x, b in entries
                )  # fmt: skip
            sizes[t] = (bits + 7) // 8
        fmmu = 0
        logical = {SM_PD_OUT: 0x0000, SM_PD_IN: 0x8000}
        for t in (SM_PD_OUT, SM_PD_IN):
            if t not in by_type or not sizes[t]:
                continue
            i, s = by_type[t]
            self.fpwr(
                station, SM_REG + 8 * i, struct.pack("<HHBBBB", s[0], sizes[t], s[2], 0, 1, 0)
            )
            typ = 2 if t == SM_PD_OUT else 1
            reg = struct.pack("<IHBBHBBB3x", logical[t], sizes[t], 0, 7, s[0], 0, typ, 1)
            self.fpwr(station, FMMU_REG + 16 * fmmu, reg)
            fmmu += 1
        self.state(station, SAFEOP, "PREOP->SAFEOP")
        self.lrw(0, bytes(max(sizes[SM_PD_OUT], 1)))
        self.state(station, OP, "SAFEOP->OP")
        return f"OP, outputs {sizes[SM_PD_OUT]} bytes, inputs {sizes[SM_PD_IN]} bytes"
