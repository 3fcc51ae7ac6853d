"""Wire faults patch the reply in place, exactly. Ref: ETG.1000.4 §5.4."""

from __future__ import annotations

from ecatsim.wire import datagram as dg
from ecatsim.wirefault import WireFault, apply


def frame() -> bytearray:
    return bytearray(dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0, b"\x10\x20", wkc=3)]))


def test_each_kind() -> None:
    f = frame()
    n = len(f)
    fault = WireFault("wkc", 1, 2)
    assert apply(fault, f, 14, n) == 1 and fault.count == 0
    assert f[-2:] == b"\x05\x00"
    f = frame()
    assert apply(WireFault("corrupt", 1), f, 14, n) == 1
    assert f[14 + 2 + 10 : 14 + 2 + 12] == b"\x10\xdf"  # the middle data byte inverted
    f = frame()
    assert apply(WireFault("circulating", 1), f, 14, n) == 1
    assert f[14 + 2 + 7] & 0x40
    assert apply(WireFault("drop", 1), frame(), 14, n) == 0
    assert apply(WireFault("duplicate", 1), frame(), 14, n) == 2
