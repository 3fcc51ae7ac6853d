"""Wire faults on the replies: drop, duplicate, corrupt a byte, change the WKC, flip the
circulating bit, for the next N frames. Armed over the control socket; the frame path
checks one attribute when nothing is armed.
"""

from __future__ import annotations

from dataclasses import dataclass

from ecatsim.wire.datagram import CIRCULATING, HEADER_LEN, LEN_MASK

KINDS = ("drop", "duplicate", "corrupt", "wkc", "circulating")


@dataclass
class WireFault:
    """One armed fault: ``kind`` for the next ``count`` replies (``value`` for wkc)."""

    kind: str
    count: int
    value: int = 1


def apply(fault: WireFault, buf: bytearray, off: int, n: int) -> int:
    """Patch the reply in place; return how many copies to send (0 = drop).

    ``off`` is the EtherCAT header offset. Ref: ETG.1000.4 §5.4 (datagram layout).
    """
    fault.count -= 1
    first = off + 2
    dlen = (buf[first + 6] | (buf[first + 7] << 8)) & LEN_MASK
    if fault.kind == "drop":
        return 0
    if fault.kind == "duplicate":
        return 2
    if fault.kind == "corrupt":
        i = first + HEADER_LEN + (dlen // 2 if dlen else 0)
        if i < n:
            buf[i] ^= 0xFF
    elif fault.kind == "wkc":
        w = first + HEADER_LEN + dlen
        if w + 2 <= n:
            v = (buf[w] | (buf[w + 1] << 8)) + fault.value
            buf[w] = v & 0xFF
            buf[w + 1] = (v >> 8) & 0xFF
    elif fault.kind == "circulating":
        buf[first + 7] ^= CIRCULATING >> 8
    return 1
