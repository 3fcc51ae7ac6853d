"""The EoE service through the mailbox, in process: exact response bytes of Set IP, Get IP,
Set Address Filter and refused requests; frames both ways; fair turns with CoE; the
counters and repeat requests the mailbox shares. Ref: ETG.1000.6 §5.7; ETG.1000.4 §5.6."""

from __future__ import annotations

import struct

from ecatsim.ethercat.segment_file import EoeConfig
from ecatsim.slave.eoe import EoeService, find_eoe
from ecatsim.slave.eoe_frag import Fragmenter, Reassembler
from ecatsim.slave.firmware import Firmware
from ecatsim.wire.eoe import IpParams, decode_header
from tests.support.tinymaster import TinyMaster, firmware_of, segment_of

EOE = 2
IP = bytes([10, 77, 0, 2])
MASK = bytes([255, 255, 255, 0])


class FakeSide:
    def __init__(self) -> None:
        self.frames: list[bytes] = []
        self.applied: list[IpParams] = []

    def write(self, frame: bytes) -> bool:
        self.frames.append(frame)
        return True

    def apply(self, params: IpParams) -> None:
        self.applied.append(params)


def setup() -> tuple[TinyMaster, Firmware, EoeService, FakeSide]:
    seg, _ = segment_of(1, device="tmc8670", eoe=EoeConfig("eoetest0", IP, MASK))
    m = TinyMaster(seg)
    m.apwr(0, 0x0800, struct.pack("<HHBBBB", 0x1000, 128, 0x26, 0, 1, 0))
    m.apwr(0, 0x0808, struct.pack("<HHBBBB", 0x1080, 128, 0x22, 0, 1, 0))
    m.apwr(0, 0x0120, b"\x02\x00")
    assert m.aprd(0, 0x0130, 1).data == b"\x02"
    fw = firmware_of(seg)
    svc = find_eoe(fw.mbx)
    assert svc is not None
    side = FakeSide()
    svc.side = side
    return m, fw, svc, side


def send(m: TinyMaster, data: bytes, counter: int, mtype: int = EOE) -> None:
    frame = struct.pack("<HHBB", len(data), 0, 0, mtype | (counter << 4)) + data
    assert m.apwr(0, 0x1000, frame.ljust(128, b"\x00")).wkc == 1


def recv(m: TinyMaster) -> bytes | None:
    r = m.aprd(0, 0x1080, 128)
    return r.data if r.wkc else None


def reply(m: TinyMaster) -> bytes:
    r = recv(m)
    assert r is not None
    n = struct.unpack_from("<H", r)[0]
    return r[: 6 + n]


def test_sii_declares_eoe() -> None:
    m, *_ = setup()
    # SII word 0x1C through the EEPROM interface: read command, address 0x1C
    m.apwr(0, 0x0502, struct.pack("<HI", 0x0100, 0x1C))
    word = struct.unpack_from("<H", m.aprd(0, 0x0508, 4).data)[0]
    assert word & 0x02 and word & 0x04  # EoE beside CoE


def test_set_ip_answers_type_3_result_0_and_applies_the_address() -> None:
    m, _, svc, side = setup()
    body = struct.pack("<I", 0x06) + bytes([9, 0, 77, 10]) + bytes([0, 255, 255, 255])
    send(m, struct.pack("<HH", 0x0102, 0) + body, 1)
    assert reply(m) == bytes.fromhex("0400 0000 0012 0301 0000".replace(" ", ""))
    assert side.applied[-1].ip == bytes([10, 77, 0, 9]) and side.applied[-1].subnet == MASK
    assert svc.params.ip == bytes([10, 77, 0, 9])


def test_get_ip_answers_type_7_with_octet_reversed_addresses() -> None:
    m, _, _svc, _ = setup()
    send(m, struct.pack("<HH", 0x0106, 0), 1)
    r = reply(m)
    assert r[:10] == bytes.fromhex("1000 0000 0012 0701 0000".replace(" ", ""))
    assert r[10:] == struct.pack("<I", 0x06) + bytes([2, 0, 77, 10]) + bytes([0, 255, 255, 255])


def test_set_address_filter_and_refused_requests() -> None:
    m, _, svc, _ = setup()
    send(m, struct.pack("<HH", 0x0104, 0) + b"\x01\x00" + bytes.fromhex("01005e000001"), 1)
    assert reply(m) == bytes.fromhex("0400 0000 0012 0501 0000".replace(" ", ""))
    assert svc.filters == (bytes.fromhex("01005e000001"),)
    send(m, struct.pack("<HH", 0x0108, 0), 2)  # Get Address Filter: not supported
    assert reply(m) == bytes.fromhex("0400 0000 0022 0901 0200".replace(" ", ""))
    send(m, struct.pack("<HH", 0x010C, 0), 3)  # a reserved type
    assert reply(m) == bytes.fromhex("0400 0000 0032 0D01 0200".replace(" ", ""))
    send(m, struct.pack("<HH", 0x0102, 0) + b"\x02\x00", 4)  # Set IP cut short
    assert reply(m) == bytes.fromhex("0400 0000 0042 0301 0100".replace(" ", ""))
    assert svc.requests == 4 and svc.refused == 3
    assert fw_errors(svc) == 0  # no mailbox error reply for any of them


def fw_errors(svc: EoeService) -> int:
    return svc.mbx.errors


def test_master_fragments_reach_the_network_side() -> None:
    m, _, svc, side = setup()
    frame = bytes(range(200)) * 7  # 1400 bytes
    f = Fragmenter(frame, 1, 128 - 10)
    c = 0
    while not f.done:
        c = c % 7 + 1
        send(m, f.next(), c)
    assert side.frames == [frame]
    assert recv(m) is None  # fragments get no reply
    st = svc.status()
    assert st["to_slave_frames"] == 1 and st["to_slave_fragments"] == 15


def test_network_frames_go_out_fragmented_and_take_turns_with_coe() -> None:
    m, _, svc, _ = setup()
    frame = bytes(range(256)) * 5 + bytes(162)  # 1442 bytes: 15 fragments
    svc.push(frame)
    # an SDO upload of 0x1018:01 while the fragments wait
    send(m, struct.pack("<HBHBI", 2 << 12, 0x40, 0x1018, 1, 0), 1, mtype=3)
    r = Reassembler()
    got = None
    seen_coe_at = None
    counters = []
    for i in range(40):
        raw = recv(m)
        if raw is None:
            break
        counters.append(raw[5] >> 4 & 7)
        n = struct.unpack_from("<H", raw)[0]
        if raw[5] & 0x0F == 3:
            seen_coe_at = i
            assert struct.unpack_from("<I", raw, 12)[0] == 0x286
            continue
        assert raw[5] & 0x0F == EOE and n <= 122
        out = r.feed(decode_header(raw[6:10]), raw[10 : 6 + n])
        if out is not None:
            got = out
    assert got == frame
    assert seen_coe_at is not None and seen_coe_at <= 1  # not behind all 15 fragments
    assert counters == [(k % 7) + 1 for k in range(16)]  # one counter sequence for all
    st = svc.status()
    assert st["to_master_frames"] == 1 and st["to_master_fragments"] == 15


def test_repeat_request_gives_the_last_fragment_again() -> None:
    m, _, svc, _ = setup()
    svc.push(bytes(range(100)))  # one fragment
    first = recv(m)
    assert first is not None
    # the master toggles the repeat request (0x0806 bit 1) and waits for the ack
    m.apwr(0, 0x080E, b"\x02")
    assert m.aprd(0, 0x080F, 1).data[0] & 0x02
    assert recv(m) == first


def test_queue_overflow_counts_drops_and_mailbox_start_clears() -> None:
    m, _fw, svc, _ = setup()
    for _ in range(40):
        svc.push(bytes(60))
    st = svc.status()
    # one in SM1, one framed and waiting for SM1, 32 queued
    assert st["to_master_dropped"] == 40 - 34
    m.apwr(0, 0x0120, b"\x01\x00")  # INIT
    m.apwr(0, 0x0120, b"\x02\x00")  # PREOP: the mailbox starts again
    assert m.aprd(0, 0x0130, 1).data == b"\x02"
    assert not svc.pending() and recv(m) is None
