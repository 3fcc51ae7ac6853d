"""Golden tests: the binary examples of the TMCM-1311 TMCL firmware manual, byte for byte,
and its tables (status codes, parameters, interrupt vectors) and example programs.

Each telegram below is copied from the manual's "Binary" example of the section named;
the checksum byte (not printed there) is the 8-bit sum of §4.1.1.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from ecatsim.tmcl import params
from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.module import ModuleConfig
from ecatsim.tmcl.program import INTERRUPTS
from tests.unit.tmcl.conftest import Bench


def tg(hexbytes: str) -> bytes:
    """A telegram from the manual's eight bytes, checksum appended."""
    b = bytes.fromhex(hexbytes.replace("$", "").replace(" ", ""))
    assert len(b) == 8
    return b + bytes([P.checksum(b)])


def reply(status: int, op: int, value: int, host: int = 2, module: int = 1) -> bytes:
    return P.encode_reply(host, module, status, op, value)


@pytest.fixture
def b() -> Iterator[Bench]:
    bench = Bench([ModuleConfig(analog=(0x12E, 0))])
    yield bench
    bench.door.close()


def test_status_code_table_4_2_1() -> None:
    assert (P.OK, P.LOADED) == (100, 101)
    assert (P.WRONG_CHECKSUM, P.INVALID_COMMAND, P.WRONG_TYPE) == (1, 2, 3)
    assert (P.INVALID_VALUE, P.EEPROM_LOCKED, P.NOT_AVAILABLE) == (4, 5, 6)


@pytest.mark.parametrize(
    ("section", "command", "answer"),
    [
        ("5.7.1 ROR 0, 10000", "$01 $01 $00 $00 $00 $00 $27 $10", (P.OK, 1, 10000)),
        ("5.7.2 ROL 0, 10000", "$01 $02 $00 $00 $00 $00 $27 $10", (P.OK, 2, 10000)),
        ("5.7.3 MST 0", "$01 $03 $00 $00 $00 $00 $00 $00", (P.OK, 3, 0)),
        ("5.7.4 MVP ABS, 0, 90000", "$01 $04 $00 $00 $00 $01 $5f $90", (P.OK, 4, 90000)),
        ("5.7.4 MVP REL, 0, -1000", "$01 $04 $01 $00 $ff $ff $fc $18", (P.OK, 4, -1000)),
        ("5.7.4 MVP COORD, 0, 8", "$01 $04 $02 $00 $00 $00 $00 $08", (P.OK, 4, 8)),
        ("5.7.5 SAP 6, 0, 200", "$01 $05 $06 $00 $00 $00 $00 $c8", (P.OK, 5, 200)),
        ("5.7.7 STAP 4, 0", "$01 $07 $04 $00 $00 $00 $00 $00", (P.OK, 7, 0)),
        ("5.7.8 RSAP 6, 0", "$01 $08 $06 $00 $00 $00 $00 $00", (P.OK, 8, 0)),
        ("5.7.11 STGP 42, 2", "$01 $0b $2a $02 $00 $00 $00 $00", (P.OK, 11, 0)),
        ("5.7.12 RSGP 42, 2", "$01 $0c $2a $02 $00 $00 $00 $00", (P.OK, 12, 0)),
        ("5.7.13 RFS START, 0", "$01 $0d $00 $00 $00 $00 $00 $00", (P.OK, 13, 0)),
        ("5.7.14 SIO 7, 2, 1", "$01 $0e $07 $02 $00 $00 $00 $01", (P.OK, 14, 1)),
        ("5.7.15 GIO 0, 1", "$01 $0f $00 $01 $00 $00 $00 $00", (P.OK, 15, 0x12E)),
        ("5.7.16 CALC MUL, -5000", "$01 $13 $02 $00 $FF $FF $EC $78", (P.OK, 0x13, -5000)),
        ("5.7.17 COMP 1000", "$01 $14 $00 $00 $00 $00 $03 $e8", (P.OK, 0x14, 1000)),
        ("5.7.25 GCO 1, 0", "$01 $1f $01 $00 $00 $00 $00 $00", (P.OK, 0x1F, 0)),
        ("5.7.26 CCO 3, 0", "$01 $20 $03 $00 $00 $00 $00 $00", (P.OK, 0x20, 0)),
        ("5.7.27 ACO 1, 0", "$01 $27 $01 $00 $00 $00 $00 $00", (P.OK, 0x27, 0)),
        ("5.7.28 CALCX MUL", "$01 $21 $02 $00 $00 $00 $00 $00", (P.OK, 0x21, 0)),
        ("5.7.29 AAP 0, 0", "$01 $22 $00 $00 $00 $00 $00 $00", (P.OK, 0x22, 0)),
        ("5.7.30 AGP 3, 2", "$01 $23 $03 $02 $00 $00 $00 $00", (P.OK, 0x23, 0)),
        ("5.7.31 CLE ETO", "$01 $24 $01 $00 $00 $00 $00 $00", (P.OK, 0x24, 0)),
        ("5.7.32 VECT 3, 500", "$01 $25 $03 $00 $00 $00 $01 $F4", (P.OK, 0x25, 500)),
        ("5.7.33 EI 255", "$01 $19 $FF $00 $00 $00 $00 $00", (P.OK, 0x19, 0)),
        ("5.7.33 EI 3", "$01 $19 $03 $00 $00 $00 $00 $00", (P.OK, 0x19, 0)),
        ("5.7.34 DI 255", "$01 $1A $FF $00 $00 $00 $00 $00", (P.OK, 0x1A, 0)),
        ("5.7.34 DI 3", "$01 $1A $03 $00 $00 $00 $00 $00", (P.OK, 0x1A, 0)),
        # program-only commands in direct mode (decision T4)
        ("5.7.18 JC GE, 10", "$01 $15 $05 $00 $00 $00 $00 $0a", (P.NOT_AVAILABLE, 0x15, 10)),
        ("5.7.19 JA 20", "$01 $16 $00 $00 $00 $00 $00 $14", (P.NOT_AVAILABLE, 0x16, 20)),
        ("5.7.20 CSUB 100", "$01 $17 $00 $00 $00 $00 $00 $64", (P.NOT_AVAILABLE, 0x17, 100)),
        ("5.7.21 RSUB", "$01 $18 $00 $00 $00 $00 $00 $00", (P.NOT_AVAILABLE, 0x18, 0)),
        ("5.7.22 WAIT POS, 0, 0", "$01 $1b $01 $00 $00 $00 $00 $00", (P.NOT_AVAILABLE, 0x1B, 0)),
        ("5.7.23 STOP", "$01 $1c $00 $00 $00 $00 $00 $00", (P.NOT_AVAILABLE, 0x1C, 0)),
        ("5.7.35 RETI", "$01 $26 $00 $00 $00 $00 $01 $00", (P.NOT_AVAILABLE, 0x26, 256)),
    ],
)
def test_binary_examples_answer_as_documented(
    b: Bench, section: str, command: str, answer: tuple[int, int, int]
) -> None:
    status, op, value = answer
    assert b.send(tg(command)) == reply(status, op, value), section


def test_5_7_6_gap_and_5_7_5_sap_current(b: Bench) -> None:
    b.send(tg("$01 $05 $06 $00 $00 $00 $00 $c8"))  # SAP 6, 0, 200
    assert b.send(tg("$01 $06 $06 $00 $00 $00 $00 $00")) == reply(P.OK, 6, 200)
    # the manual's bytes carry motor $01 (and answer 640 for a 0..255 value): motor 1 does
    # not exist on a one-axis module (decision T4)
    assert b.send(tg("$01 $06 $06 $01 $00 $00 $00 $00")) == reply(P.INVALID_VALUE, 6, 0)


def test_5_7_9_and_5_7_10_serial_address(b: Bench) -> None:
    # GGP 66, 0 -> $02 $01 $64 $0a $00 $00 $00 $01 (value 1, the default address)
    assert b.send(tg("$01 $0a $42 $00 $00 $00 $00 $00")) == tg("$02 $01 $64 $0a $00 $00 $00 $01")
    # SGP 66, 0, 3: the module answers at address 3 from now on
    assert b.send(tg("$01 $09 $42 $00 $00 $00 $00 $03")) == reply(P.OK, 9, 3)
    assert b.send(tg("$01 $0a $42 $00 $00 $00 $00 $00")) == b""
    assert b.send(tg("$03 $0a $42 $00 $00 $00 $00 $00")) == reply(P.OK, 10, 3, module=3)


def test_5_7_13_rfs_status_and_5_7_14_sio_read_back(b: Bench) -> None:
    b.send(tg("$01 $0d $00 $00 $00 $00 $00 $00"))  # RFS START: no switch, it searches
    assert b.cmd(P.RFS, 2) == (P.OK, 0)  # 0: reference search active
    b.cmd(P.RFS, 1)
    assert b.cmd(P.RFS, 2) == (P.OK, 1)
    b.send(tg("$01 $0e $07 $02 $00 $00 $00 $01"))  # SIO 7, 2, 1
    assert b.cmd(P.GIO, 7, 2) == (P.OK, 1)
    assert b.cmd(P.GIO, 255, 2) == (P.OK, 0x80)
    assert b.cmd(P.SIO, 255, 2, 3) == (P.OK, 3)  # §5.7.14: SIO 255, 2, 3
    assert b.cmd(P.GIO, 255, 2) == (P.OK, 3)


def test_5_7_37_target_position_reached_event(b: Bench) -> None:
    b.sap(4, 200_000)
    b.sap(5, 2_000_000)
    b.cmd(P.MVP, 0, 0, 1000)
    assert b.send(P.encode_command(1, P.Command(138, 0, 0, 0))) == reply(100, 138, 1)
    b.advance(0.2)
    assert bytes(b.line.sent[-9:]) == reply(128, 138, 1)


def test_5_7_39_firmware_version_and_factory_defaults(b: Bench) -> None:
    assert b.send(P.encode_command(1, P.Command(136, 0))) == b"\x021311V111"
    assert b.send(P.encode_command(1, P.Command(136, 1))) == reply(P.OK, 136, 0x051F0B01)
    b.sap(4, 1000)
    b.cmd(P.STAP, 4)
    assert b.cmd(137, 0, 0, 1) == (P.INVALID_VALUE, 1)  # value must be 1234
    assert b.send(P.encode_command(1, P.Command(137, 0, 0, 1234))) == b""  # no reply
    assert b.gap(4) == 51200


def test_download_mode_stores_the_manuals_telegrams_with_status_101(b: Bench) -> None:
    b.cmd(P.DOWNLOAD_START, 0, 0, 0)
    program = [
        "$01 $15 $05 $00 $00 $00 $00 $0a",  # JC GE, 10
        "$01 $16 $00 $00 $00 $00 $00 $14",  # JA 20
        "$01 $17 $00 $00 $00 $00 $00 $64",  # CSUB 100
        "$01 $18 $00 $00 $00 $00 $00 $00",  # RSUB
        "$01 $1b $01 $00 $00 $00 $00 $00",  # WAIT POS, 0, 0
        "$01 $1c $00 $00 $00 $00 $00 $00",  # STOP
    ]
    for addr, text in enumerate(program):
        t = tg(text)
        assert b.send(t) == reply(P.LOADED, t[1], addr)
    b.cmd(P.DOWNLOAD_END)
    for addr, text in enumerate(program):
        got = b.send(P.encode_command(1, P.Command(P.READ_MEMORY, 0, 0, addr)))
        body = bytes([2]) + tg(text)[1:8]
        assert got == body + bytes([P.checksum(body)])


def test_axis_parameter_table_6() -> None:
    # (number, range, access) as the table of §6 prints them
    table = [
        (0, -2_147_483_648, 2_147_483_647, "RW"),
        (1, -2_147_483_648, 2_147_483_647, "RW"),
        (4, 0, 327_679_999, "RWE"),
        (5, 1, 24_999_998, "RWE"),
        (6, 0, 255, "RWE"),
        (7, 0, 255, "RWE"),
        (8, 0, 1, "R"),
        (12, 0, 1, "RWE"),
        (14, -3000, 3000, "RW"),
        (25, 0, 4_294_967_295, "RWE"),
        (27, 0, 4_294_967_295, "R"),
        (29, None, None, "W"),
        (130, 0, 327_679_999, "RWE"),
        (134, 0, 255, "RW"),
        (135, 0, 131_072, "RW"),
        (136, 10, 50, "RW"),
        (138, 0, 268_435_454, "RW"),
        (140, 0, 8, "RWE"),
        (165, -3, 12, "RW"),
        (174, -64, 63, "RW"),
        (180, 0, 31, "RW"),
        (202, 0, 400, "RW"),
        (204, 0, 65535, "RWE"),
        (206, 0, 1023, "R"),
        (210, 0, 65535, "RW"),
        (212, -2_147_483_648, 2_147_483_647, "RWE"),
        (214, 1, 65535, "RWE"),
        (254, 0, 5, "RWE"),
    ]
    for n, lo, hi, access in table:
        p = params.AXIS[n]
        assert p.access == access, n
        if lo is not None:
            assert (p.lo, p.hi) == (lo, hi), n
    # §6 defaults it does print
    assert params.AXIS[140].default == 8
    assert params.AXIS[202].default == 200
    assert params.AXIS[214].default == 200
    assert (params.AXIS[113].default, params.AXIS[114].default) == (15, 255)
    assert (params.AXIS[116].default, params.AXIS[117].default) == (0, 255)
    assert (params.AXIS[134].default, params.AXIS[135].default) == (50, 100)
    assert (params.AXIS[136].default, params.AXIS[138].default) == (10, 255)
    assert params.AXIS[193].valid(136) and not params.AXIS[193].valid(9)
    assert params.AXIS[167].valid(0) and not params.AXIS[167].valid(1)


def test_global_parameter_tables_10(b: Bench) -> None:
    assert sorted(params.BANK0) == [
        *(64, 65, 66, 67, 68, 69, 70, 71, 73, 75, 76, 77, 79, 81, 83, 84, 85, 88),
        *(128, 129, 130, 132, 133),
    ]
    assert params.BANK0[65].default == 0  # 9600 baud
    assert params.BANK0[69].default == 8  # 1000 kBit/s
    assert params.BANK0[70].default == 2 and params.BANK0[71].default == 1
    p55, p56 = params.global_param(2, 55), params.global_param(2, 56)
    assert p55 is not None and p55.storable
    assert p56 is not None and not p56.storable
    assert sorted(params.BANK3) == [0, 1, 2, 27, 28, *range(39, 47)]
    assert sorted(INTERRUPTS) == [0, 1, 2, 3, 15, 21, 27, 28, *range(39, 47)]
    assert b.cmd(P.STGP, 56, 2) == (P.WRONG_TYPE, 0)
    assert b.cmd(P.SGP, 27, 3, 4) == (P.INVALID_VALUE, 4)


def test_3_3_2_example_program_moves_between_two_positions(b: Bench) -> None:
    prog = [
        (P.ROL, 0, 0, 50000),
        (P.WAIT, 0, 0, 500),
        (P.MST, 0, 0, 0),
        (P.ROR, 0, 0, 50000),
        (P.WAIT, 0, 0, 500),
        (P.MST, 0, 0, 0),
        (P.SAP, 4, 0, 50000),
        (P.SAP, 5, 0, 50000),
        (P.MVP, 0, 0, 10000),  # 8: Loop
        (P.WAIT, 1, 0, 0),
        (P.MVP, 0, 0, -100000),
        (P.WAIT, 1, 0, 0),
        (P.JA, 0, 0, 8),
    ]
    b.cmd(P.DOWNLOAD_START, 0, 0, 0)
    for c in prog:
        b.cmd(*c)
    b.cmd(P.DOWNLOAD_END)
    b.cmd(P.RUN_APP, 1, 0, 0)
    b.advance(2.5)
    assert b.gap(2) == -50000  # ROL 0, 50000 runs left for 5 s
    b.advance(10.0)
    low = high = b.gap(1)
    for _ in range(7000):  # two legs of 3.2 s: the next MVP follows WAIT POS at once
        b.advance(0.001)
        pos = b.gap(1)
        low, high = min(low, pos), max(high, pos)
    assert (low, high) == (-100000, 10000)


def test_8_11_1_closed_loop_example_program_1() -> None:
    bench = Bench()
    prog = [
        (P.SAP, 6, 0, 128),
        (P.SAP, 202, 0, 200),
        (P.SAP, 210, 0, 40000),
        (P.SAP, 4, 0, 398105),
        (P.SAP, 5, 0, 3981070),
        (P.SAP, 126, 0, 1023950),
        (P.SAP, 129, 0, 1),
        (P.GAP, 133, 0, 0),  # 7: ClWait
        (P.JC, 0, 0, 7),
        (P.MVP, 0, 0, 512000),  # 9: Loop
        (P.WAIT, 1, 0, 0),
        (P.WAIT, 0, 0, 100),
        (P.MVP, 0, 0, 0),
        (P.WAIT, 1, 0, 0),
        (P.WAIT, 0, 0, 100),
        (P.JA, 0, 0, 9),
        (P.STOP, 0, 0, 0),
    ]
    bench.cmd(P.DOWNLOAD_START, 0, 0, 0)
    for c in prog:
        bench.cmd(*c)
    bench.cmd(P.DOWNLOAD_END)
    bench.cmd(P.RUN_APP, 1, 0, 0)
    bench.advance(0.3)
    assert bench.gap(133) == 1
    assert bench.gap(18) & 4  # status word: closed loop
    reached = []
    for _ in range(60):
        bench.advance(0.1)
        if bench.gap(8):
            reached.append(bench.gap(1))
    assert any(abs(x - 512000) <= 50 for x in reached)
    assert any(abs(x) <= 50 for x in reached)
    assert bench.gap(207) == 0
    bench.door.close()
