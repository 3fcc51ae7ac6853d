"""Wire faults patch the reply in place, exactly. Ref: ETG.1000.4 §5.4."""

from __future__ import annotations

from ecatsim.faults.wire import patch
from ecatsim.wire import datagram as dg


def frame() -> bytearray:
    return bytearray(dg.ethernet_frame([dg.build(dg.Cmd.BRD, 0, 0, b"\x10\x20", wkc=3)]))


def test_each_kind() -> None:
    f = frame()
    n = len(f)
    assert patch("wkc", 2, f, 14, n) == 1
    assert f[-2:] == b"\x05\x00"
    f = frame()
    assert patch("wkc", -3, f, 14, n) == 1
    assert f[-2:] == b"\x00\x00"
    f = frame()
    assert patch("corrupt", 0, f, 14, n) == 1
    assert f[14 + 2 + 10 : 14 + 2 + 12] == b"\x10\xdf"  # the middle data byte inverted
    f = frame()
    assert patch("circulating", 0, f, 14, n) == 1
    assert f[14 + 2 + 7] & 0x40
    assert patch("drop", 0, frame(), 14, n) == 0
    assert patch("duplicate", 0, frame(), 14, n) == 2
    short = frame()[:18]
    assert patch("wkc", 1, short, 14, 18) == 1 and short == frame()[:18]  # no datagram: untouched
