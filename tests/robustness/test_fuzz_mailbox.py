"""Malformed mailbox headers and CoE/SDO/FoE requests: error replies or aborts, never a
crash or a stuck mailbox. Ref: ETG.1000.4 §5.6; ETG.1000.6 §5.6, §5.8."""

from __future__ import annotations

import random
import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from tests.golden.test_coe_exchanges import preop, recv

VALID = struct.pack("<HBHBI", 2 << 12, 0x40, 0x1018, 1, 0)


def _raw(m: object, frame: bytes) -> None:
    m.apwr(0, 0x1000, frame[:128].ljust(128, b"\x00"))  # type: ignore[attr-defined]


def test_random_mailboxes_never_stick_the_mailbox() -> None:
    m, fw = preop()
    rng = random.Random(7)
    counter = 1
    for _ in range(3000):
        kind = rng.randrange(4)
        body = rng.randbytes(rng.randrange(0, 122))
        if kind == 0:  # random everything
            frame = rng.randbytes(128)
        elif kind == 1:  # CoE with random SDO payload
            counter = counter % 7 + 1
            frame = (
                struct.pack("<HHBB", len(body) + 2, 0, 0, 3 | (counter << 4)) + b"\x00\x20" + body
            )
        elif kind == 2:  # SDO info with random payload
            counter = counter % 7 + 1
            frame = (
                struct.pack("<HHBB", len(body) + 2, 0, 0, 3 | (counter << 4)) + b"\x00\x80" + body
            )
        else:  # FoE with random payload
            counter = counter % 7 + 1
            frame = struct.pack("<HHBB", len(body), 0, 0, 4 | (counter << 4)) + body
        _raw(m, frame)
        recv(m)  # take whatever came back
        for _ in range(3):
            if recv(m) is None:
                break
    assert fw.mbx is not None and fw.mbx.errors > 0
    # still serving: a valid request gets its exact answer
    for c in (5, 6):
        _raw(m, struct.pack("<HHBB", len(VALID), 0, 0, 3 | (c << 4)) + VALID)
        r = recv(m)
        if r is not None and r[8] == 0x43:
            assert struct.unpack_from("<I", r, 12)[0] == 0x286
            return
    raise AssertionError("mailbox stuck")


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=0, max_size=120), st.integers(1, 7))
def test_any_sdo_payload_gets_a_reply(payload: bytes, counter: int) -> None:
    m, _fw = preop()
    if payload[:1] == b"\x80":
        payload = b"\x81" + payload[1:]  # an abort request is answered by silence, by design
    data = b"\x00\x20" + payload
    _raw(m, struct.pack("<HHBB", len(data), 0, 0, 3 | (counter << 4)) + data)
    r = recv(m)
    assert r is not None  # an SDO response, an abort, or a mailbox error: never silence
