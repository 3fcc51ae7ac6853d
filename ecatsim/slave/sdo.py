"""CoE SDO server: expedited, normal and segmented upload/download, Complete Access.

Every error is an ``SdoAbort`` turned into an abort frame in ``handle`` (one place), with
the full command byte 0x80.
Ref: ETG.1000.6 §5.6.2 (SDO services and frames), Table 41 (abort codes).
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import structlog

from ecatsim.slave.od import (
    ABORT_COMMAND,
    ABORT_GENERAL,
    ABORT_LENGTH,
    ABORT_READ_ONLY,
    ABORT_TOGGLE,
    ObjectDictionary,
    SdoAbort,
)
from ecatsim.wire.mailbox import CoeService

log = structlog.get_logger("ecatsim.sdo")

# command specifiers. Ref: ETG.1000.6 §5.6.2.
CCS_DOWNLOAD_SEGMENT = 0
CCS_DOWNLOAD = 1
CCS_UPLOAD = 2
CCS_UPLOAD_SEGMENT = 3
CMD_ABORT = 0x80
CA = 0x10
SDO_HDR = struct.Struct("<HBHB")  # CoE header, command, index, subindex
MIN_SEG = 7


def coe_header(service: CoeService, number: int = 0) -> bytes:
    return struct.pack("<H", (number & 0x1FF) | (int(service) << 12))


def abort_frame(index: int, sub: int, code: int) -> bytes:
    """CoE abort: SDO request service, command 0x80. Ref: ETG.1000.6 §5.6.2.7."""
    return coe_header(CoeService.SDO_REQUEST) + struct.pack("<BHBI", CMD_ABORT, index, sub, code)


class SdoServer:
    """One SDO server channel on top of the object dictionary."""

    def __init__(
        self, od: ObjectDictionary, state: Callable[[], int], max_body: Callable[[], int]
    ) -> None:
        self.od = od
        self.state = state
        self.max_body = max_body
        self.aborts = 0
        # segmented upload
        self.up_data = b""
        self.up_toggle = 0
        self.up_key = (0, 0)
        # segmented download
        self.down_buf = bytearray()
        self.down_size = 0
        self.down_toggle = 0
        self.down_key: tuple[int, int, bool] | None = None
        #: injected faults: index -> (subindex or None for any, abort code) on the next
        #: access; a toggle error in the next segment
        self.forced_aborts: dict[int, tuple[int | None, int]] = {}
        self.toggle_error_next = False

    def handle(self, data: bytes) -> bytes | None:
        """One SDO request (CoE header included) -> the reply, or None (abort request)."""
        if len(data) < 10:
            return abort_frame(0, 0, ABORT_COMMAND)
        _coe, cmd, index, sub = SDO_HDR.unpack_from(data)
        ccs = cmd >> 5
        if ccs == CCS_UPLOAD_SEGMENT:
            index, sub = self.up_key  # a segment carries data, not the object
        elif ccs == CCS_DOWNLOAD_SEGMENT and self.down_key is not None:
            index, sub = self.down_key[:2]
        try:
            return self._dispatch(cmd, index, sub, data)
        except SdoAbort as exc:
            self.aborts += 1
            self._clear()
            log.info("sdo_abort", index=f"0x{index:04X}", sub=sub, code=f"0x{exc.code:08X}")
            return abort_frame(index, sub, exc.code)
        except Exception as exc:  # a bug must not take the mailbox down
            self.aborts += 1
            self._clear()
            log.error("sdo_internal_error", index=f"0x{index:04X}", sub=sub, error=repr(exc))
            return abort_frame(index, sub, ABORT_GENERAL)

    def _clear(self) -> None:
        self.up_data = b""
        self.down_key = None
        self.down_buf = bytearray()

    def _dispatch(self, cmd: int, index: int, sub: int, data: bytes) -> bytes | None:
        ccs = cmd >> 5
        if cmd == CMD_ABORT:
            self._clear()
            return None
        if self.forced_aborts and ccs in (CCS_UPLOAD, CCS_DOWNLOAD):
            forced = self.forced_aborts.get(index)
            if forced is not None and forced[0] in (None, sub):
                del self.forced_aborts[index]
                raise SdoAbort(forced[1], "injected")
        if self.toggle_error_next and ccs in (CCS_UPLOAD_SEGMENT, CCS_DOWNLOAD_SEGMENT):
            self.toggle_error_next = False
            raise SdoAbort(ABORT_TOGGLE, "injected")
        if ccs == CCS_UPLOAD:
            return self._upload(cmd, index, sub)
        if ccs == CCS_UPLOAD_SEGMENT:
            return self._upload_segment(cmd)
        if ccs == CCS_DOWNLOAD:
            return self._download(cmd, index, sub, data)
        if ccs == CCS_DOWNLOAD_SEGMENT:
            return self._download_segment(cmd, data)
        raise SdoAbort(ABORT_COMMAND)

    # ----------------------------------------------------------------- upload

    def _upload(self, cmd: int, index: int, sub: int) -> bytes:
        """Upload initiate: expedited up to 4 bytes, else normal (+ segments).

        Ref: ETG.1000.6 §5.6.2.4, §5.6.2.5.
        """
        ca = bool(cmd & CA)
        value = self.od.read_complete(index, sub) if ca else self.od.read(index, sub)
        hdr = coe_header(CoeService.SDO_RESPONSE)
        ca_bit = CA if ca else 0
        if len(value) <= 4 and not ca:
            n = 4 - len(value)
            c = 0x43 | (n << 2)
            return hdr + struct.pack("<BHB", c, index, sub) + value.ljust(4, b"\x00")
        room = self.max_body() - 10
        if room < 1:
            raise SdoAbort(ABORT_GENERAL, "mailbox too small")
        head = struct.pack("<BHBI", 0x41 | ca_bit, index, sub, len(value))
        if len(value) <= room:
            return hdr + head + value
        self.up_data = value[room:]
        self.up_toggle = 0
        self.up_key = (index, sub)
        return hdr + head + value[:room]

    def _upload_segment(self, cmd: int) -> bytes:
        """Upload segment; the toggle bit must alternate. Ref: ETG.1000.6 §5.6.2.6."""
        if not self.up_data:
            raise SdoAbort(ABORT_COMMAND, "no segmented upload in progress")
        toggle = (cmd >> 4) & 1
        if toggle != self.up_toggle:
            raise SdoAbort(ABORT_TOGGLE)
        room = self.max_body() - 3
        chunk = self.up_data[:room]
        self.up_data = self.up_data[room:]
        last = not self.up_data
        n = max(0, MIN_SEG - len(chunk))
        c = (toggle << 4) | (n << 1) | (1 if last else 0)
        self.up_toggle ^= 1
        return coe_header(CoeService.SDO_RESPONSE) + bytes([c]) + chunk + bytes(n)

    # ----------------------------------------------------------------- download

    def _download(self, cmd: int, index: int, sub: int, data: bytes) -> bytes:
        """Download initiate: expedited or normal (+ segments). Ref: ETG.1000.6 §5.6.2.1-2."""
        ca = bool(cmd & CA)
        expedited = bool(cmd & 0x02)
        size_ind = bool(cmd & 0x01)
        if expedited:
            n = 4 - ((cmd >> 2) & 3) if size_ind else 4
            self._store(index, sub, ca, data[6 : 6 + n])
            return self._download_ok(index, sub)
        if not size_ind or len(data) < 10:
            raise SdoAbort(ABORT_COMMAND)
        total = struct.unpack_from("<I", data, 6)[0]
        payload = data[10:]
        if len(payload) >= total:
            self._store(index, sub, ca, payload[:total])
            return self._download_ok(index, sub)
        # check access before collecting segments
        if not ca:
            e = self.od.entry(index, sub)
            if e.access == "ro":
                raise SdoAbort(ABORT_READ_ONLY)
        self.down_key = (index, sub, ca)
        self.down_size = total
        self.down_buf = bytearray(payload)
        self.down_toggle = 0
        return self._download_ok(index, sub)

    def _download_segment(self, cmd: int, data: bytes) -> bytes:
        """Download segment; toggle checked, last segment stores. Ref: ETG.1000.6 §5.6.2.3."""
        if self.down_key is None:
            raise SdoAbort(ABORT_COMMAND, "no segmented download in progress")
        toggle = (cmd >> 4) & 1
        if toggle != self.down_toggle:
            raise SdoAbort(ABORT_TOGGLE)
        seg = data[3:]
        if len(seg) == MIN_SEG:
            seg = seg[: MIN_SEG - ((cmd >> 1) & 7)]
        self.down_buf += seg
        if len(self.down_buf) > self.down_size:
            raise SdoAbort(ABORT_LENGTH, "more data than announced")
        self.down_toggle ^= 1
        if cmd & 0x01:
            index, sub, ca = self.down_key
            self.down_key = None
            if len(self.down_buf) != self.down_size:
                raise SdoAbort(ABORT_LENGTH, "less data than announced")
            self._store(index, sub, ca, bytes(self.down_buf))
        return coe_header(CoeService.SDO_RESPONSE) + bytes([0x20 | (toggle << 4)]) + bytes(7)

    def _store(self, index: int, sub: int, ca: bool, value: bytes) -> None:
        if ca:
            self.od.write_complete(index, sub, value, self.state())
        else:
            self.od.write(index, sub, value, self.state())

    @staticmethod
    def _download_ok(index: int, sub: int) -> bytes:
        return coe_header(CoeService.SDO_RESPONSE) + struct.pack("<BHBI", 0x60, index, sub, 0)
