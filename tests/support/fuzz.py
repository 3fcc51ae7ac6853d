"""Seed frames and mutations for frame fuzzing (the CI test and tools/fuzz_frames.py).

The seeds are the frames a real pysoem master sent while bringing two drives to OP with DC
(``tests/data/pysoem_bringup.pcap``, made by ``tools/record_bringup.py``), plus a few
hand-built ones. Ref: issue "reliability" (fuzzing).
"""

from __future__ import annotations

import random
import struct
from pathlib import Path

from ecatsim.wire import datagram as dg

BRINGUP = Path(__file__).resolve().parents[1] / "data" / "pysoem_bringup.pcap"

HAND_BUILT = [
    dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0x0000, b"\x00\x00")]),
    dg.ethernet_frame([dg.build(dg.Cmd.FPWR, 0x1000, 0x0502, b"\x00\x01\x08\x00\x00\x00")]),
    dg.ethernet_frame([dg.build(dg.Cmd.ARMW, 0, 0x0910, bytes(8))]),
]


def read_pcap(path: Path) -> list[bytes]:
    """The frames of a little-endian classic pcap file."""
    data = path.read_bytes()
    magic = struct.unpack_from("<I", data)[0]
    if magic not in (0xA1B2C3D4, 0xA1B23C4D):
        raise ValueError(f"{path}: not a little-endian pcap file")
    frames, p = [], 24
    while p + 16 <= len(data):
        incl = struct.unpack_from("<I", data, p + 8)[0]
        frames.append(data[p + 16 : p + 16 + incl])
        p += 16 + incl
    return frames


def seed_frames() -> list[bytes]:
    return read_pcap(BRINGUP) + HAND_BUILT


def mutate(rng: random.Random, frame: bytes) -> bytes:
    """Truncate, extend, flip bits, break the EtherCAT header, use an unknown command, set
    a datagram length past the end, or randomise the tail."""
    f = bytearray(frame)
    k = rng.randrange(7)
    if k == 0:
        return bytes(f[: rng.randrange(0, len(f))])
    if k == 1:
        return bytes(f + rng.randbytes(rng.randrange(1, 64)))
    if k == 2:
        for _ in range(rng.randrange(1, 8)):
            i = rng.randrange(14, len(f))
            f[i] ^= 1 << rng.randrange(8)
        return bytes(f)
    if k == 3:
        struct.pack_into("<H", f, 14, rng.randrange(0x10000))
        return bytes(f)
    if k == 4:
        f[16] = rng.randrange(256)
        return bytes(f)
    if k == 5:
        struct.pack_into("<H", f, 22, rng.randrange(0x10000))
        return bytes(f)
    i = rng.randrange(16, len(f))
    f[i:] = rng.randbytes(len(f) - i)
    return bytes(f)
