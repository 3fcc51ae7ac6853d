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


def test_100k_fuzzed_eoe_mailboxes_keep_eoe_and_coe_working() -> None:
    """100 000 EoE mailboxes: random headers and payloads, fragment streams with losses,
    duplicates and reordering, control requests of every type, frames from the network
    side of every size. Nothing escapes, and afterwards a clean frame still gets through
    and CoE still answers. The mailboxes go straight into the engine's dispatch (the SM0
    read), with real ECAT reads of SM1 every few hundred. Ref: ETG.1000.6 §5.7."""
    from ecatsim.slave.eoe_frag import Fragmenter
    from ecatsim.wire.eoe import fragment_header
    from tests.unit.slave.test_eoe_service import recv as eoe_recv
    from tests.unit.slave.test_eoe_service import send as eoe_send
    from tests.unit.slave.test_eoe_service import setup

    m, fw, svc, side = setup()
    mbx = fw.mbx
    assert mbx is not None
    rng = random.Random(39)
    stream: list[bytes] = []
    for i in range(100_000):
        kind = rng.randrange(6)
        if kind == 0:  # random EoE header words and payload
            body = rng.randbytes(rng.randrange(0, 119))
        elif kind == 1:  # a real fragment stream, with losses, duplicates and reordering
            if not stream:
                f = Fragmenter(rng.randbytes(rng.randrange(14, 1600)), rng.randrange(16), 118)
                while not f.done:
                    stream.append(f.next())
            r = rng.random()
            if r < 0.05:
                stream.pop(0)  # lost
                continue
            if r < 0.1 and len(stream) > 1:
                stream[0], stream[1] = stream[1], stream[0]  # reordered
            body = stream[0] if r < 0.15 else stream.pop(0)  # or sent twice
        elif kind == 2:  # a control request of any type, random content
            body = struct.pack("<HH", rng.randrange(16) | 0x100, rng.randrange(65536))
            body += rng.randbytes(rng.randrange(0, 60))
        elif kind == 3:  # fragment headers with extreme numbers and offsets
            body = fragment_header(
                fragment=rng.choice((0, 1, 62, 63)),
                offset=rng.choice((0, 1, 62, 63)),
                frame=rng.randrange(16),
                last=rng.random() < 0.5,
                time_appended=rng.random() < 0.2,
            ) + rng.randbytes(rng.randrange(0, 115))
        elif kind == 4:  # a length field that lies
            body = rng.randbytes(rng.randrange(0, 119))
            frame = struct.pack("<HHBB", rng.randrange(65536), 0, 0, 2 | ((i % 7 + 1) << 4))
            mbx.dispatch((frame + body).ljust(128, b"\x00"))
            continue
        else:  # a frame from the network side, any size
            svc.push(rng.randbytes(rng.choice((0, 1, 60, 1514, 2016, 2017, 4000))))
            body = struct.pack("<HH", 0x0106, 0)  # and a Get IP beside it
        raw = struct.pack("<HHBB", len(body), 0, 0, 2 | ((i % 7 + 1) << 4)) + body
        mbx.dispatch(raw.ljust(128, b"\x00"))
        if i % 256 == 0:
            for _ in range(4):  # the master reads SM1 for real now and then
                eoe_recv(m)
        else:
            mbx.out.clear()  # replies the master never reads: dropped here
            mbx.held = None
    st = svc.status()
    assert st["to_slave_fragments"] > 10_000 and st["to_slave_frames"] > 100
    assert st["to_slave_dropped"] > 0 and st["requests"] > 10_000
    # the mailbox still works: drain what waits, then a clean frame and an SDO upload
    for _ in range(200):
        if eoe_recv(m) is None and not mbx.pending():
            break
    side.frames.clear()
    frame = bytes(range(256)) * 4
    f = Fragmenter(frame, 3, 118)
    c = 1
    eoe_send(m, fragment_header(fragment=5, offset=3, frame=9, last=True) + bytes(8), c)
    while not f.done:
        c = c % 7 + 1
        eoe_send(m, f.next(), c)
    assert side.frames == [frame]
    c = c % 7 + 1
    eoe_send(m, VALID, c, mtype=3)
    for _ in range(40):
        reply = eoe_recv(m)
        if reply is not None and reply[5] & 0x0F == 3 and reply[8] == 0x43:
            assert struct.unpack_from("<I", reply, 12)[0] == 0x286
            return
    raise AssertionError("CoE no longer answers after the EoE fuzzing")
