"""A loopback device: inputs echo the outputs, object by object.

It carries the TMC8670 process image (TMC8670 §4.1.7/4.1.8 default PDOs) and answers
``6041 <- 6040``, ``6064 <- 607A``, ``6077 <- 6071``, ``606C <- 60FF``; ``60FD`` counts the
output images received in OP. It makes process-data tests exact without motor physics.
"""

from __future__ import annotations

from collections.abc import Sequence

from ecatsim.slave.al import AlState
from ecatsim.slave.od import ObjectDictionary

#: tx object <- rx object. Ref: CiA 402 (statusword/controlword, actual/target pairs).
ECHO_PAIRS = {0x6041: 0x6040, 0x6064: 0x607A, 0x6077: 0x6071, 0x606C: 0x60FF}
COUNTER = 0x60FD


class PdoField:
    """One mapped object in a process image: byte offset and size (byte aligned)."""

    __slots__ = ("index", "offset", "size")

    def __init__(self, index: int, offset: int, size: int) -> None:
        self.index = index
        self.offset = offset
        self.size = size


def layout(entries: Sequence[tuple[int, int]]) -> tuple[list[PdoField], int]:
    """(index, bits) entries -> fields and total bytes. Gaps (index 0) are padding."""
    fields = []
    bit = 0
    for index, bits in entries:
        if index and bits % 8 == 0 and bit % 8 == 0:
            fields.append(PdoField(index, bit // 8, bits // 8))
        bit += bits
    return fields, (bit + 7) // 8


class EchoDevice:
    """Application with a fixed process image that echoes outputs into inputs."""

    def __init__(self, rx: Sequence[tuple[int, int]], tx: Sequence[tuple[int, int]]) -> None:
        self.rx_fields, self._rx_size = layout(rx)
        self.tx_fields, self._tx_size = layout(tx)
        self.values: dict[int, bytes] = {}
        self.count = 0
        self.state = AlState.INIT

    def rx_size(self) -> int:
        return self._rx_size

    def tx_size(self) -> int:
        return self._tx_size

    def set_outputs(self, data: bytes, now_ns: int) -> None:
        for f in self.rx_fields:
            self.values[f.index] = bytes(data[f.offset : f.offset + f.size])
        self.count = (self.count + 1) & 0xFFFFFFFF

    def get_inputs(self, now_ns: int) -> bytes:
        out = bytearray(self._tx_size)
        for f in self.tx_fields:
            if f.index == COUNTER:
                v = self.count.to_bytes(4, "little")[: f.size]
            else:
                v = self.values.get(ECHO_PAIRS.get(f.index, -1), b"")
            v = v[: f.size].ljust(f.size, b"\x00")
            out[f.offset : f.offset + f.size] = v
        return bytes(out)

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        if self.state == AlState.OP and state != AlState.OP:
            self.values.clear()  # safe state: outputs dropped
        self.state = state


class OdEchoDevice:
    """The echo device for CoE slaves: works on object dictionary values, so any PDO
    mapping the master configures carries the echoed objects."""

    def __init__(self, od: ObjectDictionary) -> None:
        self.od = od
        self.count = 0
        self.state = AlState.INIT

    def outputs_applied(self, now_ns: int) -> None:
        od = self.od
        for tx, rx in ECHO_PAIRS.items():
            if tx in od and rx in od:
                od.set(tx, 0, od.value(rx, 0))
        self.count = (self.count + 1) & 0xFFFFFFFF
        if COUNTER in od:
            od.set(COUNTER, 0, self.count)

    def update_inputs(self, now_ns: int) -> None:
        """Nothing moves: the echo is applied with the outputs."""

    def al_state_changed(self, state: AlState, now_ns: int) -> None:
        self.state = state
