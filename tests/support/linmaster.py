"""A LIN master for the tests: drives an in-process LIN door's pty as a UART would.

Time is the door's ManualClock: :meth:`LinMaster.wait` lets simulated time run (the
door's deadlines are honoured tick by tick, as the daemon loop does).
"""

from __future__ import annotations

import os
import select
import termios
import tty
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

from ecatsim.clock import ManualClock
from ecatsim.lin import codec
from ecatsim.lin.bus import LinBus
from ecatsim.lin.config import BusConfig, NodeConfig
from ecatsim.lin.frame import MASTER_REQUEST, SLAVE_RESPONSE, classic_checksum, data_length
from ecatsim.lin.frame import frame as lin_frame
from ecatsim.lin.frame import header as lin_header
from ecatsim.lin.node import Node
from ecatsim.lin.server import LinDoor
from ecatsim.lin.tables import Cmd, State

#: a gap the master leaves after a frame: more than T_frame_max of an 8-byte frame
GAP_NS = 20_000_000
#: how often :meth:`LinMaster.wait` shows the nodes a live bus
KEEPALIVE_NS = 500_000_000


class Bus(Protocol):
    """What the master needs of the thing it drives: time and deadlines."""

    def service(self, now_ns: int) -> None: ...

    def deadline_ns(self) -> int | None: ...


class LinMaster:
    """Speaks LIN 1.3 through ``transport`` (bytes written -> bytes answered)."""

    def __init__(self, bus: Bus, clock: ManualClock, transport: Callable[[bytes], bytes]) -> None:
        self.door = bus
        self.clock = clock
        self.raw = transport

    def wait(self, seconds: float, keepalive: bool = True) -> None:
        """Let simulated time run, servicing the door at its deadlines.

        ``keepalive``: the master keeps the bus busy as a polling master would, with a
        header nobody answers (0x3E, reserved) every 0.5 s, so the nodes see no LIN
        timeout (TMC211 §5.1.12)."""
        end = self.clock.t + int(seconds * 1e9)
        poll = self.clock.t + KEEPALIVE_NS
        while True:
            d = self.door.deadline_ns()
            t = end if d is None else min(max(d, self.clock.t), end)
            if keepalive and poll <= t and poll + GAP_NS <= end:
                t = poll
            self.clock.t = t
            self.door.service(t)
            if keepalive and t == poll and poll + GAP_NS <= end:
                self.raw(lin_header(0x3E))
                poll += KEEPALIVE_NS
            if t >= end:
                return

    def send(self, ident: int, data: bytes) -> bytes:
        """A master-published frame; returns anything that came back (should be none)."""
        out = self.raw(lin_frame(ident, data))
        self.wait(GAP_NS / 1e9)
        return out

    def read(self, ident: int) -> bytes | None:
        """A header; the answer's data bytes after checking length and checksum."""
        out = self.raw(lin_header(ident))
        n = data_length(ident)
        if not out:
            self.wait(GAP_NS / 1e9)  # a real master waits out the response time
            return None
        assert len(out) == n + 1, out.hex()
        assert classic_checksum(out[:-1]) == out[-1], out.hex()
        self.wait(GAP_NS / 1e9)
        return out[:-1]

    # --- the sheet's byte tables ---------------------------------------------------------

    def app(self, cmd: int, ad: int, params: bytes = b"", broad: bool = False) -> None:
        """A type #4 frame on 0x3C: AppCMD, command, Broad|AD, parameters, 0xFF fill."""
        b = ad & 0x7F if broad else 0x80 | ad
        data = bytes((codec.APP_CMD, 0x80 | cmd, b)) + params
        self.send(MASTER_REQUEST, data + b"\xff" * (8 - len(data)))

    def prepare(self, cmd: int, ad: int) -> None:
        """A type #8 preparing frame on 0x3C (§6.9.10)."""
        self.send(MASTER_REQUEST, bytes((codec.APP_CMD, 0x80 | cmd, 0x80 | ad)) + b"\xff" * 5)

    def full_status(self, ad: int) -> tuple[bytes | None, bytes | None]:
        """GetFullStatus: preparing frame and both type #6 reading frames (§6.11.2)."""
        self.prepare(Cmd.GET_FULL_STATUS, ad)
        return self.read(SLAVE_RESPONSE), self.read(SLAVE_RESPONSE)

    def actual_pos(self, ad: int) -> int:
        """GetActualPos through the preparing frame and 0x3D (§6.11.1)."""
        self.prepare(Cmd.GET_ACTUAL_POS, ad)
        r = self.read(SLAVE_RESPONSE)
        assert r is not None
        return codec.s16(r[1], r[2])

    def motor_param(self, ad: int, m: codec.MotorParams, broad: bool = False) -> None:
        self.app(Cmd.SET_MOTOR_PARAM, ad, codec.encode_motor_params(m), broad)

    def assign(self, ad: int, pairs: Sequence[tuple[int, int]], broad: bool = False) -> None:
        """Dynamic identifiers through 0x3C (§6.8 Table 15)."""
        self.app(Cmd.DYNAMIC_ID, ad, codec.pack_dynamic_ids(list(pairs)), broad)


class PtyPort:
    """The master's end of the door's pty, opened like a serial port."""

    def __init__(self, door: LinDoor) -> None:
        self.door = door
        self.fd = os.open(door.pty.link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        termios.tcflush(self.fd, termios.TCIOFLUSH)

    def close(self) -> None:
        os.close(self.fd)

    def __call__(self, data: bytes) -> bytes:
        """Write bytes, let the door read them (the daemon loop's job), read the answer:
        as many bytes as the door wrote to its end."""
        pty = self.door.pty
        before = pty.written
        os.write(self.fd, data)
        while select.select([pty.fd], [], [], 0.2)[0]:
            self.door.on_ready(pty.fd)
            if not select.select([pty.fd], [], [], 0)[0]:
                break
        want = pty.written - before
        out = b""
        while len(out) < want and select.select([self.fd], [], [], 2.0)[0]:
            out += os.read(self.fd, want - len(out))
        return out


def make_door(
    tmp: Path, nodes: tuple[NodeConfig, ...] = (NodeConfig(),), baud: int = 19200
) -> tuple[LinDoor, ManualClock, LinMaster]:
    """A door on a pty in ``tmp`` on a ManualClock, and a master on its pty."""
    clock = ManualClock(1_000_000_000)
    door = LinDoor(BusConfig(nodes, None, baud, "test"), tmp / "lin0", clock)
    return door, clock, LinMaster(door, clock, PtyPort(door))


def make_bus(
    nodes: tuple[NodeConfig, ...] = (NodeConfig(),), baud: int = 19200
) -> tuple[LinBus, ManualClock, LinMaster]:
    """The bus without a pty, fed directly: for the unit tests."""
    clock = ManualClock(1_000_000_000)
    bus = LinBus([Node(n, clock.t) for n in nodes], baud, clock.t)
    return bus, clock, LinMaster(bus, clock, lambda data: bus.feed(data, clock.t))


def activate(m: LinMaster, ad: int = 0, params: codec.MotorParams | None = None) -> None:
    """GetFullStatus (leaves ShutDown, §5.1.10) and SetMotorParam (RAM programmed)."""
    m.full_status(ad)
    m.motor_param(ad, params or DEFAULT_PARAMS)


#: Irun 800 mA, Ihold 100 mA, Vmax 5 (228 FS/s), Vmin 1 (1/32), Acc 3, 1/16 stepping,
#: secure position disabled
DEFAULT_PARAMS = codec.MotorParams(
    irun=0xF, ihold=0x3, vmax=5, vmin=1, secpos=0x400, acc=3, stepmode=3
)


def node_state(node: Node) -> State:
    """The node's state, read anew at each call (Table 8)."""
    return node.state
