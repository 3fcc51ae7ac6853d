#!/usr/bin/env python3
"""A small external slave firmware for an emulated TMC8460, over the PDI SPI socket.

It does what a microcontroller's slave stack does, in a hundred lines: it acknowledges
the master's AL state requests, copies the outputs (SM2) to the inputs (SM3) in SAFEOP
and OP, and serves the mailbox with a CoE SDO server (uploads, complete access too) of a small
object dictionary: the device type and the PDO description a master reads to map the
process data (12 bytes out, 17 in); anything else is aborted with 0x06020000.

    ecatsim run --iface eth1 --config segment.yaml   # a slave with firmware: external
    tools/spi_firmware.py /run/ecatsim/pdi0.sock

Every access is an SPI frame of TMC8460 §3.5.1 (3-byte addressing, reads with the wait
state byte) sent on the socket as a 2-byte little-endian length and the MOSI bytes.
"""

from __future__ import annotations

import argparse
import socket
import struct
import sys
import time

READ_WAIT, WRITE, ADDR_EXT = 3, 4, 6
AL_CONTROL, AL_STATUS, AL_STATUS_CODE = 0x0120, 0x0130, 0x0134
SM_BASE = 0x0800
DEVICE_TYPE = 0x00020192  # 0x1000: a CiA 402 drive, as the SII's device says
ABORT_NO_OBJECT = 0x06020000
ABORT_NO_SUBINDEX = 0x06090011


def _u8(v: int) -> bytes:
    return struct.pack("<B", v)


def _u16(v: int) -> bytes:
    return struct.pack("<H", v)


def _u32(v: int) -> bytes:
    return struct.pack("<I", v)


#: index -> subindex -> value: outputs 3 x 32 bits (0x7000), inputs 4 x 32 + 8 bits (0x6000)
OD: dict[int, dict[int, bytes]] = {
    0x1000: {0: _u32(DEVICE_TYPE)},
    0x1C00: {0: _u8(4), 1: _u8(1), 2: _u8(2), 3: _u8(3), 4: _u8(4)},
    0x1C12: {0: _u8(1), 1: _u16(0x1600)},
    0x1C13: {0: _u8(1), 1: _u16(0x1A00)},
    0x1600: {0: _u8(3), **{i: _u32(0x70000020 | (i << 8)) for i in (1, 2, 3)}},
    0x1A00: {
        0: _u8(5),
        **{i: _u32(0x60000020 | (i << 8)) for i in (1, 2, 3, 4)},
        5: _u32(0x60000508),
    },
}


def upload(index: int, sub: int, complete: bool) -> bytes | int:
    """An object's value (complete access: subindex 0 as 16 bits, then every entry), or
    the abort code."""
    obj = OD.get(index)
    if obj is None:
        return ABORT_NO_OBJECT
    if complete:
        return obj[0] + b"\x00" + b"".join(obj[k] for k in sorted(obj) if k > 0)
    return obj.get(sub, ABORT_NO_SUBINDEX)


MBX_COE = 3
COE_SDO_REQUEST, COE_SDO_RESPONSE = 2, 3


class Spi:
    """The PDI SPI of one emulated chip, on its socket."""

    def __init__(self, path: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.connect(path)

    def frame(self, mosi: bytes) -> bytes:
        self.sock.sendall(struct.pack("<H", len(mosi)) + mosi)
        out = b""
        while len(out) < len(mosi):
            got = self.sock.recv(len(mosi) - len(out))
            if not got:
                raise ConnectionError("the daemon closed the PDI socket")
            out += got
        return out

    @staticmethod
    def _address(addr: int, cmd: int) -> bytes:
        return bytes(
            [(addr >> 5) & 0xFF, ((addr & 0x1F) << 3) | ADDR_EXT, ((addr >> 13) << 5) | (cmd << 2)]
        )

    def events(self) -> int:
        """AL event request 0x0220:0x0222 from a NOP's address phase (it also reloads the
        PDI watchdog)."""
        got = self.frame(bytes([0x00, ADDR_EXT, 0x00]))
        return got[0] | (got[1] << 8) | (got[2] << 16)

    def read(self, addr: int, n: int) -> bytes:
        mosi = self._address(addr, READ_WAIT) + b"\xff" + bytes(n - 1) + b"\xff"
        return self.frame(mosi)[4:]

    def write(self, addr: int, data: bytes) -> None:
        self.frame(self._address(addr, WRITE) + data)


class Firmware:
    def __init__(self, spi: Spi) -> None:
        self.spi = spi
        self.state = 1
        self.mbx_count = 0

    def sm(self, n: int) -> tuple[int, int]:
        start, length = struct.unpack("<HH", self.spi.read(SM_BASE + 8 * n, 4))
        return start, length

    def al_control(self) -> None:
        ctrl = struct.unpack("<H", self.spi.read(AL_CONTROL, 2))[0]
        self.state = ctrl & 0x0F
        self.spi.write(AL_STATUS_CODE, b"\x00\x00")
        self.spi.write(AL_STATUS, struct.pack("<H", self.state))

    def copy_process_data(self) -> None:
        (out_start, out_len), (in_start, in_len) = self.sm(2), self.sm(3)
        outputs = self.spi.read(out_start, out_len) if out_len else b""
        if in_len:
            self.spi.write(in_start, outputs[:in_len].ljust(in_len, b"\x00"))

    def mailbox(self) -> None:
        (rx, rx_len), (tx, tx_len) = self.sm(0), self.sm(1)
        mail = self.spi.read(rx, rx_len)
        length, _addr, _chan, kind = struct.unpack_from("<HHBB", mail)
        if kind & 0x0F != MBX_COE or length < 10:
            return
        coe, cmd, index, sub = struct.unpack_from("<HBHB", mail, 6)
        if coe >> 12 != COE_SDO_REQUEST or cmd & 0xE0 != 0x40:  # only uploads are served
            return
        value = upload(index, sub, bool(cmd & 0x10))
        if isinstance(value, int):  # an abort travels as an SDO request (ETG.1000.6)
            service, sdo = COE_SDO_REQUEST, struct.pack("<BHBI", 0x80, index, sub, value)
        elif len(value) <= 4 and not cmd & 0x10:  # expedited, size indicated
            service = COE_SDO_RESPONSE
            sdo = struct.pack("<BHB", 0x43 | ((4 - len(value)) << 2), index, sub) + value.ljust(
                4, b"\x00"
            )
        else:  # normal upload: the size, then the data
            service = COE_SDO_RESPONSE
            sdo = struct.pack("<BHBI", 0x41 | (cmd & 0x10), index, sub, len(value)) + value
        self.mbx_count = self.mbx_count % 7 + 1
        body = struct.pack("<H", service << 12) + sdo
        head = struct.pack("<HHBB", len(body), 0, 0, MBX_COE | (self.mbx_count << 4))
        self.spi.write(tx, (head + body).ljust(tx_len, b"\x00"))

    def step(self) -> None:
        ev = self.spi.events()
        if ev & 0x0001:  # AL control (§5.32 Table 46 bit 0)
            self.al_control()
        if ev & 0x0100:  # SM0: the master wrote a mailbox
            self.mailbox()
        if self.state in (4, 8):  # SAFEOP, OP
            self.copy_process_data()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("socket", help="the slave's pdi_socket")
    p.add_argument("--period-us", type=int, default=200, help="poll period")
    args = p.parse_args()
    for _ in range(100):  # the daemon may still be starting
        try:
            spi = Spi(args.socket)
            break
        except (FileNotFoundError, ConnectionRefusedError):
            time.sleep(0.05)
    else:
        print(f"spi_firmware: no daemon at {args.socket}", file=sys.stderr)
        return 1
    fw = Firmware(spi)
    print("spi_firmware: serving", args.socket, flush=True)
    try:
        while True:
            fw.step()
            time.sleep(args.period_us / 1e6)
    except (ConnectionError, KeyboardInterrupt):
        return 0


if __name__ == "__main__":
    sys.exit(main())
