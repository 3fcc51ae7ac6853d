"""100 000 random byte streams on the LIN bus: the bus never stops, errors are counted,
and a valid frame afterwards is answered.

Streams are pure noise, valid headers with random data, and valid TMC211 frames with a
byte changed. Between streams the master leaves a gap longer than a frame (as a real
master does after an error), in simulated time. Ref: TMC211 §6.7 Table 14.
"""

from __future__ import annotations

import random

from ecatsim.lin import codec
from ecatsim.lin.config import NodeConfig
from ecatsim.lin.frame import MASTER_REQUEST, SLAVE_RESPONSE, frame, header, protect
from ecatsim.lin.tables import Cmd, State
from tests.support.linmaster import GAP_NS, LinMaster, activate, make_bus

NODES = (
    NodeConfig(name="a", otp=bytes((0, 0, 1, 0, 0, 0, 0, 0))),
    NodeConfig(name="b", otp=bytes((0, 0, 2, 0, 0, 0, 0, 0))),
)
SEEDS = [
    frame(MASTER_REQUEST, bytes((0x80, 0x81, 0x81, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF))),
    frame(MASTER_REQUEST, bytes((0x80, 0x89, 0x82, 0x82, 0x51, 0x03, 0x00, 0xEC))),
    frame(MASTER_REQUEST, bytes((0x80, 0x8B, 0x81, 0x01, 0x00, 0x82, 0x02, 0x00))),
    frame(MASTER_REQUEST, bytes((0x80, 0x91, 0x00, 0x53, 0x48, 0xF9, 0xFF, 0xFF))),
    header(SLAVE_RESPONSE),
    header(0x05),
    frame(0x28, bytes((0x8B, 0x00, 0x01, 0x00))),
]


def stream(rng: random.Random) -> bytes:
    kind = rng.randrange(3)
    if kind == 0:
        return rng.randbytes(rng.randrange(1, 40))
    if kind == 1:
        return bytes((0x00, 0x55, protect(rng.randrange(64)))) + rng.randbytes(rng.randrange(10))
    f = bytearray(rng.choice(SEEDS))
    f[rng.randrange(len(f))] = rng.randrange(256)
    if f[-1] & 1 and len(f) > 4:
        del f[rng.randrange(3, len(f)) :]
    return bytes(f)


def answered(m: LinMaster, ad: int) -> bool:
    """A valid exchange: GetActualPos prepared on 0x3C, read on 0x3D (§6.11.1)."""
    m.prepare(Cmd.GET_ACTUAL_POS, ad)
    r = m.read(SLAVE_RESPONSE)
    return r is not None and r[0] == 0x80 | ad


def test_100k_random_streams_then_a_valid_frame_is_answered(count: int = 100_000) -> None:
    bus, clock, m = make_bus(NODES)
    for ad in (1, 2):
        activate(m, ad)
    rng = random.Random(20261125)
    fed = 0
    for i in range(count):
        data = stream(rng)
        fed += len(data)
        bus.feed(data, clock.t)
        clock.t += GAP_NS
        if i % 10_000 == 9_999:
            bus.service(clock.t)
            for n in bus.nodes:  # a fuzzed frame may have sent a node to sleep
                if n.state in (State.SLEEP, State.SHUTDOWN):
                    m.read(0x3E)  # wakes it
                    m.full_status(n.address)
            assert answered(m, 1) and answered(m, 2), i
    p = bus.parser
    assert fed > 1_000_000
    assert p.noise > 100_000
    assert p.errors["HEADER"] > 100_000 and p.errors["DATA"] > 1_000
    assert p.errors["TIMEOUT"] > 1_000
    m.wait(0.05)
    assert answered(m, 1) and answered(m, 2)
    # and a command still works: a node moves
    m.motor_param(1, codec.MotorParams(8, 2, 5, 1, 0x400, 0, 3, 0, 3))
    m.app(Cmd.SET_POSITION, 1, bytes((0x02, 0x00, 0x7F, 0, 0)))
    m.wait(0.5)
    assert m.actual_pos(1) == 0x200
