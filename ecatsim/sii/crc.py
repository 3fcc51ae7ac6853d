"""CRC-8 of the SII ESC configuration area.

Polynomial x^8 + x^2 + x + 1 (0x07), initial value 0xFF, no reflection, over bytes 0..13
(words 0-6); the result is the low byte of word 7. Ref: ETG.2010 §2.1 (Checksum).
"""

from __future__ import annotations


def _table() -> tuple[int, ...]:
    out = []
    for b in range(256):
        c = b
        for _ in range(8):
            c = ((c << 1) ^ 0x07) & 0xFF if c & 0x80 else (c << 1) & 0xFF
        out.append(c)
    return tuple(out)


_TABLE = _table()


def crc8(data: bytes) -> int:
    """CRC-8 (poly 0x07, init 0xFF) of ``data``. Ref: ETG.2010 §2.1."""
    c = 0xFF
    for b in data:
        c = _TABLE[c ^ b]
    return c
