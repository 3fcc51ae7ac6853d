"""The frame recorder keeps each frame's bytes exactly, whatever buffer it comes in: a
bytearray, a contiguous or strided memoryview, shorter or longer than a slot (its copy
is one view copy in the compiled core, not a loop per byte). Run against the compiled
core and the pure-Python one alike.

Ref: docs/decisions.md (P, the frame recorder's copy).
"""

from __future__ import annotations

from ecatsim.ethercat.recorder import FrameRecorder

SLOT = 1536  # recorder.SLOT (a C constant in the compiled core, not importable there)


def test_the_recorder_keeps_every_frame_byte_for_byte() -> None:
    rec = FrameRecorder(depth=4)
    raw = bytearray(range(256)) * 8  # 2048 bytes, more than a slot
    rec.record(raw, 60)
    rec.record(memoryview(raw)[10:], 100)  # a view that starts inside the buffer
    rec.record(memoryview(raw)[::2], 64)  # a strided view
    rec.record(raw, len(raw))  # longer than a slot: the slot's worth is kept
    assert rec.last() == [
        bytes(raw[:60]),
        bytes(raw[10:110]),
        bytes(raw[0:128:2]),
        bytes(raw[:SLOT]),
    ]


def test_a_frame_longer_than_its_buffer_or_empty_keeps_what_there_is() -> None:
    rec = FrameRecorder(depth=3)
    rec.record(bytearray(b"\xaa" * 70), 70)
    rec.record(bytearray(b"\x01\x02\x03"), 10)  # n beyond the buffer: the buffer's bytes
    rec.record(bytearray(b"\x55" * 8), 0)  # nothing: an empty slot, left out of last()
    assert rec.last() == [b"\xaa" * 70, b"\x01\x02\x03"]
    rec.record(bytearray(b"\x07" * 5), 5)  # the ring wraps: the oldest slot is reused
    assert rec.last() == [b"\x01\x02\x03", b"\x07" * 5]
