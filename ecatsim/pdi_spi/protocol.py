"""The PDI SPI datagram: address/command phase, data phase, errors. Ref: TMC8460 §3.5.1.

One call of :func:`transfer` is one chip-select frame: the MOSI bytes the microcontroller
clocks out while the chip select is active, and the MISO bytes the chip clocks back.

- 2-byte addressing: byte 0 = A[12:5], byte 1 = A[4:0] C[2:0] (addresses below 0x2000).
- 3-byte addressing: byte 1 carries the address extension command (6), byte 2 =
  A[15:13] C[2:0] 00. Byte 2 may be repeated with command 6 to pad the frame; the last
  copy carries the real command (§3.5.1 "Command 6").
- During the address/command bytes the chip answers with the AL event request registers
  0x0220, 0x0221 and, in 3-byte mode, 0x0222 (Table 46); padding bytes answer 0x00.
- Read (2) and read with wait state (3): the master sends 0x00 except for the last byte,
  0xFF, which terminates the read. Write (4): every data byte is written.
- Errors (a reserved command, a frame that ends inside the address phase, a missing or
  early read termination, a read without wait state too fast for the chip) count in
  0x030D and leave their code in 0x030E (§5.36, §5.37 Table 51).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

CMD_NOP = 0
CMD_READ = 2
CMD_READ_WAIT = 3
CMD_WRITE = 4
CMD_ADDR_EXT = 6
#: Table 3: commands 1, 5 and 7 are reserved
RESERVED = frozenset({1, 5, 7})

#: 0x030E bits (Table 51)
ERR_BUSY = 0x08  # busy violation during a read access
ERR_NO_TERMINATION = 0x10  # read termination missing
ERR_AFTER_TERMINATION = 0x20  # access continued after the read termination byte

#: the byte that ends a read, and the wait state byte of command 3
READ_END = 0xFF
#: the pause the chip needs between the address phase and the first data byte of a plain
#: read (§3.5.1 "Command 2")
READ_PAUSE_NS = 240


class SpiTarget(Protocol):
    """What the SPI slave of the chip reaches: the PDI face of the ESC."""

    def read(self, addr: int, n: int) -> bytes: ...

    def write(self, addr: int, data: bytes) -> bool: ...

    def events(self) -> bytes:
        """AL event request 0x0220:0x0222, read without side effects."""
        ...

    def accessed(self) -> None:
        """A complete access: the PDI watchdog is triggered (§5.40)."""
        ...

    def interface_error(self, code: int) -> None:
        """Count a PDI interface error (0x030D) and keep its code (0x030E)."""
        ...


@dataclass(frozen=True, slots=True)
class SpiTiming:
    """What the socket cannot carry: the SPI clock the microcontroller would use.

    A plain read (command 2) needs ``READ_PAUSE_NS`` between the address phase and the
    first data byte. Without a pause of its own the master gives the chip half an SCK
    period, or a whole one in late-sample mode (0x0150 bit 5). ``read_pause_ns`` set
    means the master pauses that long, as §3.5.1 asks.
    """

    sck_hz: int = 1_000_000
    read_pause_ns: int = 0

    def plain_read_in_time(self, late_sample: bool) -> bool:
        half_periods = 2 if late_sample else 1
        gap_ns = self.read_pause_ns + half_periods * 500_000_000 // self.sck_hz
        return gap_ns >= READ_PAUSE_NS


def _error_code(cmd: int | None, flags: int) -> int:
    """0x030E: CMD[2:1] in bits 7:6, the flags, and the SPI clock count modulo 8 in bits
    2:0, which is 0 for a frame of whole bytes."""
    return ((((cmd or 0) >> 1) & 3) << 6) | flags


def transfer(
    target: SpiTarget, mosi: bytes, timing: SpiTiming = SpiTiming(), late_sample: bool = False
) -> bytes:
    """One chip-select frame: MOSI in, MISO out (``len(mosi)`` bytes)."""
    n = len(mosi)
    miso = bytearray(n)
    if n == 0:
        return b""  # chip select without clocks: nothing happened
    ev = target.events()
    miso[0] = ev[0]
    if n < 2:
        target.interface_error(_error_code(None, 0))
        return bytes(miso)
    miso[1] = ev[1]
    addr = (mosi[0] << 5) | (mosi[1] >> 3)
    cmd = mosi[1] & 7
    i = 2
    if cmd == CMD_ADDR_EXT:  # 3-byte addressing, with any number of padding copies
        while True:
            if i >= n:
                target.interface_error(_error_code(CMD_ADDR_EXT, 0))
                return bytes(miso)
            b = mosi[i]
            if i == 2:
                miso[i] = ev[2]
            cmd = (b >> 2) & 7
            addr = (addr & 0x1FFF) | ((b >> 5) << 13)
            i += 1
            if cmd != CMD_ADDR_EXT:
                break
    if cmd in RESERVED:
        target.interface_error(_error_code(cmd, 0))
        return bytes(miso)
    if cmd == CMD_NOP:
        target.accessed()
        return bytes(miso)
    if cmd == CMD_WRITE:
        if i < n:
            target.write(addr, bytes(mosi[i:]))
        target.accessed()
        return bytes(miso)
    # a read: the wait state byte first (command 3), then data up to the 0xFF
    flags = 0
    if cmd == CMD_READ_WAIT:
        i += 1  # the wait state byte; its MISO is undefined (0x00 here)
    elif not timing.plain_read_in_time(late_sample):
        flags |= ERR_BUSY
    if i >= n:
        target.interface_error(_error_code(cmd, flags | ERR_NO_TERMINATION))
        return bytes(miso)
    data = mosi[i:]
    end = data.find(READ_END)
    if end < 0:
        flags |= ERR_NO_TERMINATION
        count = len(data)
    else:
        count = end + 1
        if count < len(data):
            flags |= ERR_AFTER_TERMINATION
    if not flags & ERR_BUSY:
        got = _read(target, addr, count)
        miso[i : i + count] = got
    if flags:
        target.interface_error(_error_code(cmd, flags))
    else:
        target.accessed()
    return bytes(miso)


def _read(target: SpiTarget, addr: int, count: int) -> bytes:
    """``count`` bytes from ``addr``; the address wraps at 64 KiB as the counter does."""
    first = min(count, 0x10000 - addr)
    got = target.read(addr, first)
    if first < count:
        got += target.read(0, count - first)
    return got
