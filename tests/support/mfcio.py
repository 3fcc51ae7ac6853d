"""MFCIO process images for tests: MB0 (96 bytes, the master's outputs) packed from
register names, MB1 (36 bytes, the inputs) unpacked into them. Ref: TMC8460 §5.53."""

from __future__ import annotations

from ecatsim.mfcio import regs as R


def mb0(**values: int) -> bytes:
    """The 96-byte MB0 image with the named writable registers set (ENC_X_W for ENC_X)."""
    out = bytearray(R.MB0_SIZE)
    for name, v in values.items():
        r = R.reg(name)
        assert r.writable and r.mb is not None, name
        off = r.mb - R.MB0_START
        out[off : off + r.size] = (v & ((1 << (8 * r.size)) - 1)).to_bytes(r.size, "little")
    return bytes(out)


def mb1(data: bytes, start: int = R.MB1_START) -> dict[str, int]:
    """The readable registers in an image of MB1 (or of a part starting at ``start``)."""
    out = {}
    for r in R.REGISTERS:
        if r.writable or r.mb is None:
            continue
        off = r.mb - start
        if off >= 0 and off + r.size <= len(data):
            out[r.name] = int.from_bytes(data[off : off + r.size], "little")
    return out


def s32(v: int) -> int:
    return v - (1 << 32) if v & 0x80000000 else v
