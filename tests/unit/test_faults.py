"""The fault engine in process: each kind, each trigger, exact effects.

A Daemon serves a LoopbackLink on a ManualClock; the test is the master.
Ref: issue "reliability" (fault kinds, triggers); docs/decisions.md R1-R6.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from ecatsim.errors import UserError
from ecatsim.ethercat.daemon import Daemon
from ecatsim.ethercat.segment import Segment
from ecatsim.ethercat.segment_file import load_segment
from ecatsim.faults.spec import FaultSpecError, parse_fault
from ecatsim.link.loopback import LoopbackLink
from ecatsim.wire import datagram as dg
from tests.support.tinymaster import Reply, decode, drive_of, segment_of

SDO_REQ = struct.pack("<H", 2 << 12)
MS = 1_000_000


class LoopMaster:
    """A master on the loopback wire, with the real daemon loop step in between."""

    def __init__(self, n: int = 1, device: str = "echo") -> None:
        self.seg, self.clock = segment_of(n, device=device)
        self.link = LoopbackLink()
        self.daemon = Daemon(self.link, self.seg)
        self.faults = self.daemon.faults
        self.buf = bytearray(2048)

    def inject(self, **raw: object) -> int:
        return self.faults.add(parse_fault(raw), self.clock.now_ns())

    def frames(self, datagrams: list[bytes]) -> list[list[Reply]]:
        """Send one frame; every frame that comes back now (0, 1 or 2 copies)."""
        self.link.master_send(dg.ethernet_frame(datagrams))
        assert self.daemon.handle_one(self.buf)
        return self.collect()

    def collect(self) -> list[list[Reply]]:
        out = []
        while (raw := self.link.master_recv()) is not None:
            out.append(decode(raw, 14))
        return out

    def one(self, datagram: bytes) -> Reply | None:
        got = self.frames([datagram])
        assert len(got) <= 1
        return got[0][0] if got else None

    def brd(self) -> Reply | None:
        return self.one(dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2)))

    def later(self, dt_ns: int) -> None:
        """Time passes; the daemon's timers run."""
        self.clock.advance(dt_ns)
        self.daemon._service_timers()

    def apwr(self, pos: int, ado: int, data: bytes) -> Reply | None:
        return self.one(dg.build(dg.Cmd.APWR, (-pos) & 0xFFFF, ado, data))

    def aprd(self, pos: int, ado: int, n: int) -> Reply | None:
        return self.one(dg.build(dg.Cmd.APRD, (-pos) & 0xFFFF, ado, bytes(n)))


def wkcs(m: LoopMaster, n: int) -> list[int]:
    out = []
    for _ in range(n):
        r = m.brd()
        out.append(-1 if r is None else r.wkc)
    return out


# ----------------------------------------------------------------- specs


@pytest.mark.parametrize(
    ("raw", "msg"),
    [
        ({"kind": "unplug"}, "kind: 'unplug' is not a fault kind"),
        ({"kind": "wkc"}, "value: required for kind wkc"),
        ({"kind": "drop", "code": 3}, "code: not a parameter of kind drop"),
        ({"kind": "drop", "after_frames": 1, "after_s": 1}, "after_s: give at most one"),
        ({"kind": "al_fall", "code": 1, "on_state": "running"}, "on_state: 'running' is not"),
        ({"kind": "drop", "probability": 1.5}, "probability: expected a number 0.0..1.0"),
        ({"kind": "drop", "colour": 1}, "colour: unknown field"),
        ({"kind": "delay", "value": 0}, "value: the delay in microseconds"),
        ({"kind": "mbx_drop", "slave": 0, "alias": 5}, "alias: give either slave"),
    ],
)
def test_bad_specs_name_the_field(raw: dict[str, object], msg: str) -> None:
    with pytest.raises(FaultSpecError, match=msg):
        parse_fault(raw)


def test_segment_yaml_faults_error_names_file_and_entry(tmp_path: Path) -> None:
    p = tmp_path / "seg.yaml"
    p.write_text("slaves: [{device: echo}]\nfaults:\n  - {kind: drop}\n  - {kind: wkc}\n")
    with pytest.raises(UserError) as e:
        load_segment(p)
    assert str(e.value) == f"{p}: faults[1]: value: required for kind wkc"
    p.write_text("slaves: [{device: echo}]\nfaults:\n  - {kind: wkc, value: -1, on_state: op}\n")
    (spec,) = load_segment(p).faults
    assert spec.kind == "wkc" and spec.value == -1 and spec.count == 1


def test_unknown_slave_or_alias_is_refused() -> None:
    m = LoopMaster(2)
    with pytest.raises(FaultSpecError, match="slave: no slave 2"):
        m.inject(kind="al_fall", code=0x1A, slave=2)
    with pytest.raises(FaultSpecError, match="alias: no slave has the alias 0x1234"):
        m.inject(kind="al_fall", code=0x1A, alias=0x1234)
    assert not m.faults.active


# ----------------------------------------------------------------- wire faults and triggers


def test_idle_engine_costs_nothing_and_leaves_frames_alone() -> None:
    m = LoopMaster(2)
    assert not m.faults.active and not m.faults.wire_live
    assert wkcs(m, 3) == [2, 2, 2]


def test_after_frames_then_count() -> None:
    m = LoopMaster(2)
    m.inject(kind="wkc", value=-1, count=2, after_frames=3)
    assert wkcs(m, 6) == [2, 2, 2, 1, 1, 2]
    assert not m.faults.active  # used up: the engine is idle again


def test_drop_duplicate_corrupt_circulating() -> None:
    m = LoopMaster(1)
    m.inject(kind="drop")
    assert m.frames([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))]) == []
    m.inject(kind="duplicate")
    got = m.frames([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))])
    assert len(got) == 2 and got[0] == got[1] and got[0][0].wkc == 1
    m.inject(kind="corrupt")
    r = m.brd()
    assert r is not None and r.data == b"\x01\xff"  # AL status 0x0001 with byte 1 inverted
    m.inject(kind="circulating")
    r = m.brd()
    assert r is not None and r.flags & 0x4000
    r = m.brd()
    assert r is not None and r.data == b"\x01\x00" and not r.flags & 0x4000


def test_delay_holds_the_reply_back() -> None:
    m = LoopMaster(1)
    m.inject(kind="delay", value=2000)  # 2 ms
    assert m.frames([dg.build(dg.Cmd.BRD, 0, 0x0130, bytes(2))]) == []
    assert m.daemon._deadline() == m.clock.now_ns() + 2 * MS
    m.later(1 * MS)
    assert m.collect() == []
    m.later(1 * MS)
    (late,) = m.collect()
    assert late[0].wkc == 1
    assert m.brd() is not None  # the next one is on time


def test_probability_is_reproducible_from_the_seed() -> None:
    def pattern(seed: int) -> list[int]:
        m = LoopMaster(1)
        m.inject(kind="drop", probability=0.3, seed=seed)
        return wkcs(m, 200)

    a = pattern(7)
    assert a == pattern(7)
    assert a != pattern(8)
    assert 30 <= a.count(-1) <= 90  # about 60 of 200


def test_time_window_holds_a_link_fault(tmp_path: Path) -> None:
    m = LoopMaster(3)
    m.inject(kind="link_down", slave=1, port=1, after_s=1.0, for_s=2.0)
    assert wkcs(m, 1) == [3]
    m.later(999 * MS)
    assert wkcs(m, 1) == [3]
    m.later(1 * MS)
    assert wkcs(m, 1) == [2]  # the third slave is cut off
    r = m.aprd(1, 0x0110, 2)
    assert r is not None and r.data == bytes([0x13, 0x56])  # port 1 no link, loop closed
    r = m.aprd(1, 0x0311, 1)
    assert r is not None and r.data == b"\x01"  # lost link counter port 1
    m.later(2000 * MS)
    assert wkcs(m, 1) == [3]
    assert not m.faults.active


def test_on_state_fires_when_the_slave_gets_there() -> None:
    m = LoopMaster(1, "tmc8670")
    m.inject(kind="wkc", value=5, on_state="preop")
    assert wkcs(m, 2) == [1, 1]
    m.apwr(0, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(0, 0x0808, struct.pack("<HHBBBB", 0x1080, 128, 0x22, 0, 1, 0))
    r = m.apwr(0, 0x0120, b"\x02\x00")
    assert r is not None and r.wkc == 1  # the frame that requests PREOP is not touched
    assert wkcs(m, 2) == [6, 1]  # the one after the state was reached is


# ----------------------------------------------------------------- slave faults


def preop(m: LoopMaster, tx_len: int = 128) -> None:
    m.apwr(0, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(0, 0x0808, struct.pack("<HHBBBB", 0x1080, tx_len, 0x22, 0, 1, 0))
    m.apwr(0, 0x0120, b"\x02\x00")
    r = m.aprd(0, 0x0130, 2)
    assert r is not None and r.data == b"\x02\x00"


def sdo(m: LoopMaster, body: bytes, counter: int, size: int = 128) -> bytes:
    frame = struct.pack("<HHBB", len(body), 0, 0, 3 | (counter << 4)) + body
    r = m.apwr(0, 0x1000, frame.ljust(128, b"\x00"))
    assert r is not None and r.wkc == 1
    r = m.aprd(0, 0x1080, size)
    assert r is not None and r.wkc == 1
    return r.data


def upload(index: int, sub: int) -> bytes:
    return SDO_REQ + struct.pack("<BHBI", 0x40, index, sub, 0)


def test_sdo_abort_on_the_next_access_to_that_object() -> None:
    m = LoopMaster(1, "tmc8670")
    preop(m)
    m.inject(kind="sdo_abort", index=0x1018, sub=1, code=0x06020000)
    r = sdo(m, upload(0x1018, 2), 1)
    assert r[8] == 0x43  # another subindex: not affected
    r = sdo(m, upload(0x1018, 1), 2)
    assert r[6:16] == SDO_REQ + struct.pack("<BHBI", 0x80, 0x1018, 1, 0x06020000)
    r = sdo(m, upload(0x1018, 1), 3)
    assert r[8] == 0x43 and struct.unpack_from("<I", r, 12)[0] == 0x286  # used up


def test_mailbox_error_reply_with_the_code() -> None:
    m = LoopMaster(1, "tmc8670")
    preop(m)
    m.inject(kind="mbx_error", code=0x0006)
    r = sdo(m, upload(0x1000, 0), 1)
    # length 4, type 0 (error), service 1, code 6 (invalid size)
    assert r[:10] == bytes.fromhex("0400 0000 0010 0100 0600".replace(" ", ""))
    assert sdo(m, upload(0x1000, 0), 2)[8] == 0x43


def test_wrong_counter_repeats_the_previous_one() -> None:
    m = LoopMaster(1, "tmc8670")
    preop(m)
    first = sdo(m, upload(0x1000, 0), 1)
    m.inject(kind="mbx_counter")
    second = sdo(m, upload(0x1000, 0), 2)
    third = sdo(m, upload(0x1000, 0), 3)
    counters = [r[5] >> 4 for r in (first, second, third)]
    assert counters == [1, 1, 2]


def test_toggle_error_in_a_segmented_upload() -> None:
    m = LoopMaster(1, "tmc8670")
    preop(m, tx_len=20)  # 14-byte mailbox body: the 7-byte device name needs segments
    r = sdo(m, upload(0x1008, 0), 1, 20)
    assert r[8] == 0x41 and struct.unpack_from("<I", r, 12)[0] == 7 and r[16:20] == b"TMC8"
    m.inject(kind="sdo_toggle")
    r = sdo(m, SDO_REQ + bytes([0x60]) + bytes(7), 2, 20)
    assert r[6:16] == SDO_REQ + struct.pack("<BHBI", 0x80, 0x1008, 0, 0x05030000)


def test_mailbox_drop_counts_requests() -> None:
    m = LoopMaster(1, "tmc8670")
    preop(m)
    m.inject(kind="mbx_drop", count=2)
    for c in (1, 2):
        frame = struct.pack("<HHBB", 10, 0, 0, 3 | (c << 4)) + upload(0x1000, 0)
        m.apwr(0, 0x1000, frame.ljust(128, b"\x00"))
        r = m.aprd(0, 0x1080, 128)
        assert r is not None and r.wkc == 0  # nothing to read
    assert sdo(m, upload(0x1000, 0), 3)[8] == 0x43


def al(m: LoopMaster, pos: int = 0) -> tuple[int, int]:
    r = m.aprd(pos, 0x0130, 6)
    assert r is not None
    s, _, code = struct.unpack("<HHH", r.data)
    return s, code


def test_al_refuse_and_fall() -> None:
    m = LoopMaster(1, "tmc8670")
    m.inject(kind="al_refuse", code=0x0011)
    m.apwr(0, 0x0120, b"\x02\x00")
    assert al(m) == (0x11, 0x0011)  # INIT + error, the injected code
    m.inject(kind="al_fall", code=0x001A, after_frames=1)
    m.apwr(0, 0x0120, b"\x04\x00")  # (refused: SMs not configured) - the frame that counts
    assert al(m)[0] & 0x10


def test_power_cycle_resets_registers_and_cuts_the_slave_off_meanwhile() -> None:
    m = LoopMaster(2, "tmc8670")
    m.apwr(0, 0x0010, b"\x01\x10")
    m.apwr(1, 0x0010, b"\x02\x10")
    preop(m)
    m.inject(kind="power_cycle", slave=1, value=50)  # at once
    assert wkcs(m, 1) == [1]  # slave 1 is dark
    r = m.aprd(0, 0x0110, 2)
    assert r is not None and r.data[0] & 0x20 == 0  # slave 0: port 1 no link
    m.later(50 * MS)
    assert wkcs(m, 1) == [2]
    r = m.aprd(1, 0x0010, 2)
    assert r is not None and r.data == b"\x00\x00"  # station address back to reset
    assert al(m, 1) == (0x01, 0)  # INIT, no error
    assert al(m, 0)[0] == 0x02  # slave 0 was not touched
    r = m.aprd(1, 0x0502, 2)
    assert r is not None and r.data[1] & 0x80 == 0  # EEPROM loaded, not busy


def test_drive_fault_is_held_until_cleared() -> None:
    m = LoopMaster(1, "tmc8670")
    fid = m.inject(kind="overcurrent")
    drive = drive_of(m.seg, 0)
    assert "overcurrent" in drive.injected
    assert m.faults.status()[0]["kind"] == "overcurrent"
    assert m.faults.clear(fid, m.clock.now_ns()) == 1
    assert "overcurrent" not in drive.injected and not m.faults.active


def test_segment_type() -> None:
    assert isinstance(LoopMaster().seg, Segment)


@pytest.mark.parametrize(
    ("state", "want"),
    [("init", 0x11), ("preop", 0x12)],
)
def test_al_fall_never_raises_the_state(state: str, want: int) -> None:
    """A fall in INIT or PREOP stays there with the error bit and the code: never up to
    SAFEOP (decision O2)."""
    m = LoopMaster(1, "tmc8670")
    if state == "preop":
        preop(m)
    m.inject(kind="al_fall", code=0x001B)
    m.aprd(0, 0x0130, 2)  # the frame on which the fault fires
    assert al(m) == (want, 0x001B)


def test_al_fall_target_is_the_lower_of_the_state_and_safeop() -> None:
    from ecatsim.faults.engine import fall_target
    from ecatsim.slave.al import AlState

    assert [fall_target(s) for s in AlState] == [
        AlState.INIT,
        AlState.PREOP,
        AlState.BOOT,
        AlState.SAFEOP,
        AlState.SAFEOP,
    ]
