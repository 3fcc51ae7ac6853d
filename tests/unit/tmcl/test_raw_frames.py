"""Raw telegrams: checksum, status codes, addressing, framing of a broken byte stream.

Ref: TMCM-1311 TMCL firmware manual §4.1, §4.1.1, §4.2, §4.2.1, §10.1 (66, 73, 75, 76).
"""

from __future__ import annotations

import socket

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import ModuleConfig
from tests.support.tmcl import exchange, frame, served
from tests.unit.tmcl.conftest import Bench


def test_checksum_is_the_8_bit_sum() -> None:
    # §5.7.1 example ROR 0, 10000: 01 01 00 00 00 00 27 10 -> 0x01+0x01+0x27+0x10 = 0x39
    assert frame(P.ROR, 0, 0, 10000) == bytes.fromhex("0101000000002710" + "39")
    assert P.checksum(bytes([0xFF, 0xFF, 0x03])) == 0x01


def test_wrong_checksum_answers_status_1(bench: Bench) -> None:
    bad = bytearray(frame(P.GAP, 4))
    bad[8] ^= 0x55
    out = bench.send(bytes(bad))
    assert out[:4] == bytes([2, 1, P.WRONG_CHECKSUM, P.GAP])
    assert out[8] == P.checksum(out[:8])
    assert bench.door.bad_checksums == 1


def test_unknown_command_2_wrong_type_3_bad_value_or_motor_4(bench: Bench) -> None:
    assert bench.cmd(99)[0] == P.INVALID_COMMAND
    assert bench.cmd(200)[0] == P.INVALID_COMMAND
    assert bench.cmd(P.GAP, 99)[0] == P.WRONG_TYPE  # no axis parameter 99
    assert bench.cmd(P.SAP, 8, 0, 1)[0] == P.WRONG_TYPE  # read-only
    assert bench.cmd(P.MVP, 3, 0, 0)[0] == P.WRONG_TYPE  # MVP types 0-2
    assert bench.cmd(P.GGP, 0, 1)[0] == P.WRONG_TYPE  # bank 1 holds nothing
    assert bench.cmd(P.SAP, 6, 0, 256) == (P.INVALID_VALUE, 256)  # 0..255
    assert bench.cmd(P.SAP, 5, 0, 0)[0] == P.INVALID_VALUE  # 1..24999998
    assert bench.cmd(P.SAP, 167, 0, 1)[0] == P.INVALID_VALUE  # 0 or 2..15
    assert bench.cmd(P.GAP, 1, 1)[0] == P.INVALID_VALUE  # motor 1: one axis only
    assert bench.cmd(P.ROR, 0, 0, 268_435_455)[0] == P.INVALID_VALUE
    assert bench.cmd(P.SGP, 0, 7, 1)[0] == P.INVALID_VALUE  # no bank 7
    assert bench.gap(6) == 128  # nothing of it took effect


def test_eeprom_lock_answers_5_and_program_only_commands_6(bench: Bench) -> None:
    assert bench.value(P.SGP, 73, 0, 1234) == 1234
    assert bench.value(P.GGP, 73) == 1
    assert bench.cmd(P.STAP, 4)[0] == P.EEPROM_LOCKED
    assert bench.cmd(P.STGP, 0, 2)[0] == P.EEPROM_LOCKED
    assert bench.cmd(P.SGP, 65, 0, 2)[0] == P.EEPROM_LOCKED  # bank 0 lives in the EEPROM
    assert bench.cmd(P.SGP, 3, 2, 5)[0] == P.OK  # user variables are RAM
    assert bench.value(P.SGP, 73, 0, 4321) == 4321
    assert bench.value(P.GGP, 73) == 0
    assert bench.cmd(P.STAP, 4)[0] == P.OK
    for op in (P.JA, P.JC, P.CSUB, P.RSUB, P.WAIT, P.STOP, P.RETI):
        assert bench.cmd(op)[0] == P.NOT_AVAILABLE


def test_other_addresses_get_no_reply_and_replies_use_the_host_address(bench: Bench) -> None:
    assert bench.send(frame(P.GAP, 4, address=2)) == b""
    bad = bytearray(frame(P.GAP, 4, address=3))
    bad[8] ^= 1
    assert bench.send(bytes(bad)) == b""  # a broken telegram for another module
    assert bench.value(P.SGP, 76, 0, 9) == 9
    out = bench.send(frame(P.GGP, 66))
    assert out[:4] == bytes([9, 1, P.OK, P.GGP])
    # SGP 66: the reply still comes from the old address, the next command needs the new
    out = bench.send(frame(P.SGP, 66, 0, 5))
    assert out[:3] == bytes([9, 1, P.OK])
    assert bench.send(frame(P.GAP, 4)) == b""
    assert bench.send(frame(P.GAP, 4, address=5))[:3] == bytes([9, 5, P.OK])


def test_two_modules_on_one_line_answer_their_own_address() -> None:
    b = Bench([ModuleConfig(address=1), ModuleConfig(address=2)])
    assert b.cmd(P.SAP, 4, 0, 1000, address=2)[0] == P.OK
    assert b.cmd(P.GAP, 4, address=1) == (P.OK, 51200)
    assert b.cmd(P.GAP, 4, address=2) == (P.OK, 1000)
    b.door.close()


def test_telegram_pause_delays_the_reply(bench: Bench) -> None:
    # the pause applies from the reply to the SGP that sets it (15 ms)
    assert bench.send(frame(P.SGP, 75, 0, 15)) == b""
    bench.advance(0.016)
    assert bytes(bench.line.sent)[:4] == bytes([2, 1, P.OK, P.SGP])
    assert bench.send(frame(P.GAP, 4)) == b""
    bench.advance(0.014)
    assert len(bench.line.sent) == 9
    bench.advance(0.002)
    assert len(bench.line.sent) == 18
    assert bench.line.sent[-9:-5] == bytes([2, 1, P.OK, P.GAP])


def test_split_telegrams_join_and_a_pause_drops_a_partial_one(bench: Bench) -> None:
    f = frame(P.GAP, 4)
    assert bench.send(f[:4]) == b""
    assert bench.send(f[4:])[:3] == bytes([2, 1, P.OK])
    # garbage, then a pause longer than the receiver's restart: the next telegram is clean
    assert bench.send(b"\x01\x02\x03") == b""
    bench.advance(0.05)
    assert bench.send(f)[:3] == bytes([2, 1, P.OK])
    # without a pause the garbage shifts the stream: 9 bytes, a bad checksum at worst
    bench.send(b"\x01\x02")
    out = bench.send(f)
    assert len(out) in (0, 9)


def test_serial_heartbeat_stops_the_motor(bench: Bench) -> None:
    bench.value(P.SGP, 68, 0, 100)
    bench.value(P.ROR, 0, 0, 10_000)
    bench.advance(0.09)
    assert bench.gap(2) == 10_000
    bench.advance(0.15)  # no command for more than 100 ms
    bench.advance(1.0)
    assert bench.gap(2) == 0
    assert bench.gap(3) == 0


def test_a_client_that_disconnects_mid_frame_does_not_stop_the_server() -> None:
    with served() as s:
        for _ in range(20):
            c = socket.create_connection(("127.0.0.1", s.port))
            c.sendall(frame(P.GAP, 4)[:5])
            c.close()
        garbage = socket.create_connection(("127.0.0.1", s.port))
        garbage.sendall(bytes(range(256)) * 4)
        garbage.close()
        c = socket.create_connection(("127.0.0.1", s.port))
        c.settimeout(5)
        reply = exchange(c, frame(P.GAP, 4))
        assert reply[:4] == bytes([2, 1, P.OK, P.GAP])
        assert int.from_bytes(reply[4:8], "big") == 51200
        c.close()
        assert s.in_loop(lambda: s.door.disconnects) >= 21
