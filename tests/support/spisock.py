"""One chip-select frame over a PDI/MFC SPI socket, for in-process tests: the length-prefixed
MOSI bytes out, the door host served, exactly as many MISO bytes back (README "Your own
slave firmware over the PDI SPI socket")."""

from __future__ import annotations

import socket
import struct
from typing import Protocol


class Served(Protocol):
    def serve(self) -> object: ...


def spi_frame(c: socket.socket, host: Served, mosi: bytes) -> bytes:
    """Send ``mosi`` as one frame on ``c``, let ``host`` answer, return the MISO bytes."""
    c.sendall(struct.pack("<H", len(mosi)) + mosi)
    host.serve()
    c.settimeout(1)
    out = b""
    while len(out) < len(mosi):
        out += c.recv(len(mosi) - len(out))
    return out
