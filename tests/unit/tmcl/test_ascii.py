"""The ASCII interface: 139 enters it, command lines and replies, echo modes, BIN leaves.

Ref: TMCM-1311 TMCL firmware manual §4.4.1-4.4.4, §5.6.6, §5.7.38.
"""

from __future__ import annotations

from ecatsim.tmcl import ascii as A
from ecatsim.tmcl import protocol as P
from tests.support.tmcl import frame
from tests.unit.tmcl.conftest import Bench


def test_parse_the_manuals_command_lines() -> None:
    assert A.parse("AMVP ABS, 1, 50000") == A.Parsed(1, P.Command(P.MVP, 0, 1, 50000))
    assert A.parse("A MVP ABS, 1, 50000") == A.Parsed(1, P.Command(P.MVP, 0, 1, 50000))
    assert A.parse("AROL 2, 500") == A.Parsed(1, P.Command(P.ROL, 0, 2, 500))
    assert A.parse("A MST 1") == A.Parsed(1, P.Command(P.MST, 0, 1, 0))
    assert A.parse("ABIN") == A.Parsed(1, special="BIN")
    assert A.parse("CGAP 0, 1") == A.Parsed(3, P.Command(P.GAP, 0, 1, 0))
    assert A.parse("ARFS STATUS, 0") == A.Parsed(1, P.Command(P.RFS, 2, 0, 0))
    assert A.parse("AJA 5") == A.Parsed(1, error=P.INVALID_COMMAND)  # not in ASCII mode
    assert A.parse("ASAP x, 0, 1") == A.Parsed(1, error=P.WRONG_TYPE)
    assert A.parse("   ") is None


def test_reply_format_of_the_manual() -> None:
    # §4.4.2: AGAP 0, 1 -> "BA 100 -5000" with host address 2, module address 1
    assert A.reply_text(2, 1, 100, -5000) == b"BA 100 -5000\r"


def test_ascii_round_trip_with_echo_and_back_to_binary(bench: Bench) -> None:
    out = bench.send(frame(P.ASCII_MODE))
    assert out == P.encode_reply(2, 1, P.OK, P.ASCII_MODE, 0)
    assert bench.send(b"ASAP 4") == b"ASAP 4"  # every character echoed (67 bits 4/5: 00)
    assert bench.send(b", 0, 1000\r") == b", 0, 1000\rBA 100 1000\r"
    assert bench.send(b"AGAP 4, 0\r") == b"AGAP 4, 0\rBA 100 1000\r"
    assert bench.send(b"AGAP 99, 0\r").endswith(b"BA 3 0\r")
    assert bench.send(b"AGAX\x08P 4\r").endswith(b"BA 100 1000\r")  # backspace edits
    assert bench.send(b"BGAP 4\r") == b""  # module 2 is not on this line: no echo (T30)
    assert bench.send(b"ABIN\r") == b"ABIN\r"
    assert bench.send(frame(P.GAP, 4))[:3] == bytes([2, 1, P.OK])


def test_echo_modes_of_global_parameter_67(bench: Bench) -> None:
    bench.value(P.SGP, 67, 0, 16)  # echo the whole line after CR
    bench.send(frame(P.ASCII_MODE))
    assert bench.send(b"AGAP 6") == b""
    assert bench.send(b"\r") == b"AGAP 6\rBA 100 128\r"
    bench.m.gp0[67] = 32  # no echo, only the reply
    assert bench.send(b"AGAP 6\r") == b"BA 100 128\r"
    assert bench.send(b"ARUN\r") == b"BA 100 0\r"
    assert bench.m.interp.state == 1
    assert bench.send(b"ASTOP\r") == b"BA 100 0\r"
    assert bench.m.interp.state == 0


def test_start_up_in_ascii_mode() -> None:
    b = Bench()
    b.value(P.SGP, 67, 0, 33)  # bit 0: start in ASCII mode; bit 5: no echo
    from ecatsim.tmcl.server import LineState
    from tests.unit.tmcl.conftest import FakeLine

    line = FakeLine()
    b.door._add(line)
    st = b.door.lines[line.fileno()]
    assert isinstance(st, LineState) and st.ascii is b.m
    b.door.receive(st, b"AGGP 66, 0\r", b.clock.now_ns())
    assert bytes(line.sent) == b"BA 100 1\r"
    b.door.close()


def test_echo_only_when_the_module_is_addressed() -> None:
    """§4.4.4: "every character that is entered is echoed back when the module is
    addressed" (decision T30): on a line with modules 1 and 3, a line for address 2 is
    neither echoed nor answered; each module's own 67 chooses the echo of its lines."""
    from ecatsim.tmcl.module import ModuleConfig

    b = Bench([ModuleConfig(address=1), ModuleConfig(address=3)])
    b.door.modules[1].gp0[67] = 16  # module 3: the whole line after CR
    b.send(frame(P.ASCII_MODE))
    assert b.send(b"B") == b""  # nobody has address 2
    assert b.send(b"GAP 4\r") == b""
    assert b.send(b"  ") == b""  # spaces before the address character wait for it
    assert b.send(b"A") == b"  A"
    assert b.send(b"GAP 6\r") == b"GAP 6\rBA 100 128\r"
    assert b.send(b"CGAP 6") == b""
    assert b.send(b"\r") == b"CGAP 6\rBC 100 128\r"
    assert b.send(b"X\x08AGGP 66\r") == b"AGGP 66\rBA 100 1\r"  # X erased: A decides
    b.door.close()
