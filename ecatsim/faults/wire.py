"""Wire faults on a reply, patched in place: drop, duplicate, corrupt a byte, change the
WKC, flip the circulating bit. (A delay is the daemon's: it holds the reply back.)
"""

from __future__ import annotations

from ecatsim.wire.datagram import CIRCULATING, HEADER_LEN, LEN_MASK


def patch(kind: str, value: int, buf: bytearray, off: int, n: int) -> int:
    """Patch the reply at ``buf[:n]`` (EtherCAT header at ``off``) in place; return how
    many copies to send (0 = drop). The first datagram carries the damage.

    Ref: ETG.1000.4 §5.4 (datagram layout: header 10 bytes, data, WKC 2 bytes).
    """
    first = off + 2
    if kind == "drop":
        return 0
    if kind == "duplicate":
        return 2
    if first + HEADER_LEN > n:
        return 1
    dlen = (buf[first + 6] | (buf[first + 7] << 8)) & LEN_MASK
    if kind == "corrupt":
        i = first + HEADER_LEN + (dlen // 2 if dlen else 0)
        if i < n:
            buf[i] ^= 0xFF
    elif kind == "wkc":
        w = first + HEADER_LEN + dlen
        if w + 2 <= n:
            v = (buf[w] | (buf[w + 1] << 8)) + value
            buf[w] = v & 0xFF
            buf[w + 1] = (v >> 8) & 0xFF
    elif kind == "circulating":
        buf[first + 7] ^= CIRCULATING >> 8
    return 1
