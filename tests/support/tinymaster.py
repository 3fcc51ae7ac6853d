"""A tiny in-process EtherCAT master for golden-byte and in-process tests.

It builds real frames (Ethernet + EtherCAT header + datagrams), runs them through
``Segment.process`` exactly as the daemon does, and decodes the replies.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from ecatsim.clock import ManualClock
from ecatsim.device.drive import Drive
from ecatsim.ethercat.assembly import build_segment
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import SegmentConfig, SlaveConfig
from ecatsim.slave.firmware import Firmware
from ecatsim.wire import datagram as dg
from ecatsim.wire.frame import ecat_offset, mark_processed


@dataclass
class Reply:
    """One datagram of a reply frame."""

    cmd: int
    idx: int
    adp: int
    ado: int
    data: bytes
    wkc: int
    irq: int
    flags: int


def decode(frame: bytes | bytearray, off: int) -> list[Reply]:
    """Decode the datagrams of an EtherCAT frame starting at the EtherCAT header."""
    out = []
    p = off + 2
    while True:
        cmd, idx, adp, ado, lf, irq = dg.HEADER.unpack_from(frame, p)
        n = lf & dg.LEN_MASK
        data = frame[p + 10 : p + 10 + n]
        (wkc,) = struct.unpack_from("<H", frame, p + 10 + n)
        out.append(Reply(cmd, idx, adp, ado, bytes(data), wkc, irq, lf & 0xF800))
        if not lf & dg.MORE_FOLLOWS:
            return out
        p += 12 + n


def segment_of(
    n: int = 1, device: str = "echo", clock: Any = None, **kw: object
) -> tuple[Segment, ManualClock]:
    """A segment of n slaves on a manual clock (or on ``clock``)."""
    clock = ManualClock(1_000_000_000) if clock is None else clock
    cfg = SegmentConfig(tuple(SlaveConfig(device=device, serial=i + 1, **kw) for i in range(n)))  # type: ignore[arg-type]
    return build_segment(cfg, clock), clock


class TinyMaster:
    """Sends frames through a segment in process."""

    def __init__(self, segment: Segment, clock: ManualClock | None = None) -> None:
        self.seg = segment
        self.clock = clock
        self.last_frame = b""

    def frame(self, datagrams: list[bytes], *, service: bool = True) -> list[Reply] | None:
        """Send one frame of datagrams; None if the frame was destroyed."""
        raw = bytearray(dg.ethernet_frame(datagrams))
        n = len(raw)
        off = ecat_offset(raw, n, True)
        if not self.seg.process(raw, off, n):
            self.seg.service()
            return None
        mark_processed(raw)
        self.last_frame = bytes(raw)
        if service:
            self.seg.service()
        return decode(raw, off)

    def one(self, datagram: bytes, **kw: bool) -> Reply:
        r = self.frame([datagram], **kw)
        if r is None:
            raise AssertionError("frame destroyed")
        return r[0]

    # convenience ------------------------------------------------------------------
    def aprd(self, pos: int, ado: int, n: int) -> Reply:
        return self.one(dg.build(dg.Cmd.APRD, (-pos) & 0xFFFF, ado, bytes(n)))

    def apwr(self, pos: int, ado: int, data: bytes) -> Reply:
        return self.one(dg.build(dg.Cmd.APWR, (-pos) & 0xFFFF, ado, data))

    def fprd(self, station: int, ado: int, n: int) -> Reply:
        return self.one(dg.build(dg.Cmd.FPRD, station, ado, bytes(n)))

    def fpwr(self, station: int, ado: int, data: bytes) -> Reply:
        return self.one(dg.build(dg.Cmd.FPWR, station, ado, data))

    def brd(self, ado: int, n: int) -> Reply:
        return self.one(dg.build(dg.Cmd.BRD, 0, ado, bytes(n)))

    def bwr(self, ado: int, data: bytes) -> Reply:
        return self.one(dg.build(dg.Cmd.BWR, 0, ado, data))

    def lrw(self, lad: int, data: bytes) -> Reply:
        return self.one(dg.build_logical(dg.Cmd.LRW, lad, data))

    def u16(self, station: int, ado: int) -> int:
        return int(struct.unpack("<H", self.fprd(station, ado, 2).data)[0])


def firmware_of(seg: Segment, k: int = 0) -> Firmware:
    """Slave ``k``'s firmware, ecatsim's own (a slave on the PDI socket has another)."""
    fw = seg.firmware[k]
    assert isinstance(fw, Firmware), fw
    return fw


def firmwares(seg: Segment) -> list[Firmware]:
    """Every slave's firmware, each ecatsim's own (:func:`firmware_of`)."""
    return [firmware_of(seg, k) for k in range(len(seg.firmware))]


def drive_of(seg: Segment, k: int) -> Drive:
    """Slave ``k``'s TMC8670 drive."""
    drive = firmware_of(seg, k).device
    assert isinstance(drive, Drive), drive
    return drive
