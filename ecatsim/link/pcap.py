"""Classic pcap writer (stdlib only) for the daemon's frame recorder.

File header: magic, version 2.4, thiszone 0, sigfigs 0, snaplen, linktype. Each record:
seconds, sub-second (micro- or nanoseconds, told apart by the magic), captured length,
original length, then the captured bytes. Written little-endian; readers detect the byte
order from the magic. Wireshark's EtherCAT dissector decodes linktype 1 (Ethernet) frames
with EtherType 0x88A4.

Ref: IETF draft-ietf-opsawg-pcap (pcap capture file format; magic 0xA1B2C3D4 = µs,
0xA1B23C4D = ns); tcpdump.org link-layer header types (LINKTYPE_ETHERNET = 1).
"""

from __future__ import annotations

import os
import struct
import time
from types import TracebackType
from typing import BinaryIO

MAGIC_USEC = 0xA1B2C3D4
MAGIC_NSEC = 0xA1B23C4D
LINKTYPE_ETHERNET = 1
DEFAULT_SNAPLEN = 65535
FILE_HEADER = struct.Struct("<IHHiIII")
RECORD_HEADER = struct.Struct("<IIII")


class PcapWriter:
    """Append frames to a new classic pcap file at ``path``.

    ``nanosecond`` selects nanosecond timestamps (else microseconds). ``write`` takes an
    optional timestamp in nanoseconds since the epoch (default: now). Use as a context
    manager or call ``close``.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        nanosecond: bool = True,
        snaplen: int = DEFAULT_SNAPLEN,
        linktype: int = LINKTYPE_ETHERNET,
    ) -> None:
        if snaplen <= 0:
            raise ValueError(f"snaplen {snaplen}: must be positive")
        self.path = os.fspath(path)
        self.nanosecond = nanosecond
        self.snaplen = snaplen
        self.linktype = linktype
        self.count = 0
        self._f: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        magic = MAGIC_NSEC if nanosecond else MAGIC_USEC
        self._f.write(FILE_HEADER.pack(magic, 2, 4, 0, 0, snaplen, linktype))

    def write(self, frame: bytes | bytearray | memoryview, ts_ns: int | None = None) -> None:
        """Append one frame (truncated to ``snaplen``) stamped ``ts_ns`` (default now)."""
        if ts_ns is None:
            ts_ns = time.time_ns()
        sec, frac = divmod(ts_ns, 1_000_000_000)
        if not self.nanosecond:
            frac //= 1000
        orig = len(frame)
        cap = min(orig, self.snaplen)
        f = self._f
        f.write(RECORD_HEADER.pack(sec & 0xFFFFFFFF, frac, cap, orig))
        f.write(frame if cap == orig else memoryview(frame)[:cap])
        self.count += 1

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self) -> PcapWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
