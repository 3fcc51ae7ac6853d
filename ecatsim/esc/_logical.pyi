"""Type stub of the compiled logical datagram (ecatsim/esc/_logical.c)."""

from typing import Any

def run(escs: list[Any], cmd: int, lad: int, buf: bytearray, d0: int, dlen: int) -> int: ...
