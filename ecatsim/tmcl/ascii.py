"""The TMCL ASCII interface: command lines in, text replies out.

A line is the module's address character (``A`` for address 1), optional spaces, the
mnemonic and its operands, and CR. The reply is the host's and the module's address
characters, the status and the value in decimal, and CR. ``BIN`` returns to binary mode;
``RUN`` and ``STOP`` start and stop the program. Global parameter 67 bits 4/5 choose the
echo.

Ref: TMCM-1311 TMCL firmware manual §4.4 (4.4.1-4.4.4), §5.6.6, §5.7.38, §10.1 (67).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from ecatsim.tmcl import protocol as P
from ecatsim.tmcl.protocol import Command

#: the direct-mode commands ASCII mode takes (§4.4.3) and the operands each is written with
LAYOUT: dict[str, tuple[int, tuple[str, ...]]] = {
    "ROR": (P.ROR, ("motor", "value")),
    "ROL": (P.ROL, ("motor", "value")),
    "MST": (P.MST, ("motor",)),
    "MVP": (P.MVP, ("type", "motor", "value")),
    "SAP": (P.SAP, ("type", "motor", "value")),
    "GAP": (P.GAP, ("type", "motor")),
    "STAP": (P.STAP, ("type", "motor")),
    "RSAP": (P.RSAP, ("type", "motor")),
    "SGP": (P.SGP, ("type", "motor", "value")),
    "GGP": (P.GGP, ("type", "motor")),
    "STGP": (P.STGP, ("type", "motor")),
    "RSGP": (P.RSGP, ("type", "motor")),
    "RFS": (P.RFS, ("type", "motor")),
    "SIO": (P.SIO, ("type", "motor", "value")),
    "GIO": (P.GIO, ("type", "motor")),
    "SCO": (P.SCO, ("type", "motor", "value")),
    "GCO": (P.GCO, ("type", "motor")),
    "CCO": (P.CCO, ("type", "motor")),
    **{f"UF{i}": (P.UF0 + i, ("type", "motor", "value")) for i in range(8)},
}

#: symbolic types (§5.7.4 MVP, §5.7.13 RFS)
TYPE_NAMES: dict[str, dict[str, int]] = {
    "MVP": {"ABS": 0, "REL": 1, "COORD": 2},
    "RFS": {"START": 0, "STOP": 1, "STATUS": 2},
}

#: the special commands of ASCII mode (§4.4.3)
SPECIAL = ("BIN", "RUN", "STOP")


@dataclass(frozen=True, slots=True)
class Parsed:
    """One command line: for ``address``, a command, a special word, or a status to
    answer at once (a line the module cannot take)."""

    address: int
    command: Command | None = None
    special: str | None = None
    error: int | None = None


def address_char(address: int) -> str:
    """``A`` for address 1, ``B`` for 2 ... (§4.4.1)."""
    return chr(ord("A") + (address - 1) % 256) if 1 <= address <= 26 else "@"


_LINE = re.compile(r"^\s*([A-Za-z])\s*([A-Za-z]+[0-7]?)\s*(.*?)\s*$")


def parse(line: str) -> Parsed | None:
    """A command line; None when it addresses nobody (blank, no address character)."""
    m = _LINE.match(line)
    if m is None:
        return None
    addr = ord(m.group(1).upper()) - ord("A") + 1
    word = m.group(2).upper()
    rest = m.group(3)
    if word in SPECIAL and not rest:
        return Parsed(addr, special=word)
    spec = LAYOUT.get(word)
    if spec is None:
        return Parsed(addr, error=P.INVALID_COMMAND)
    opcode, fields = spec
    ops = [x for x in re.split(r"[,\s]+", rest) if x] if rest else []
    if len(ops) > len(fields):
        return Parsed(addr, error=P.INVALID_VALUE)
    got = {"type": 0, "motor": 0, "value": 0}
    for name, text in zip(fields, ops, strict=False):
        if name == "type" and text.upper() in TYPE_NAMES.get(word, {}):
            got[name] = TYPE_NAMES[word][text.upper()]
            continue
        try:
            got[name] = int(text, 0)
        except ValueError:
            return Parsed(addr, error=P.WRONG_TYPE if name == "type" else P.INVALID_VALUE)
    if not 0 <= got["type"] <= 255 or not 0 <= got["motor"] <= 255:
        return Parsed(addr, error=P.INVALID_VALUE)
    if not -(1 << 31) <= got["value"] < (1 << 32):
        return Parsed(addr, error=P.INVALID_VALUE)
    value = P.to_signed(got["value"])
    return Parsed(addr, Command(opcode, got["type"], got["motor"], value))


def reply_text(host: int, module: int, status: int, value: int) -> bytes:
    """``BA 100 -5000`` and CR (§4.4.2)."""
    return f"{address_char(host)}{address_char(module)} {status} {value}\r".encode()


MAX_LINE = 256


class LineEditor:
    """Characters in, complete command lines out, with the echo global parameter 67 asks
    for (§4.4.4): bits 4/5 00 every character, 01 the whole line after CR, 10 none.

    A line is echoed only when it addresses a module ("when the module is addressed",
    §4.4.4; decision T30): the first character that is not a space decides, and with it
    whose parameter 67 chooses the echo. Until then nothing is echoed; the spaces before
    it are echoed with it."""

    def __init__(self) -> None:
        self.buf = bytearray()
        #: the echo mode (67) of the module the line addresses; None: nobody addressed
        #: (no echo); -1: the address character has not come yet
        self.mode: int | None = -1

    def _decide(self, echo_mode: Callable[[int], int | None]) -> None:
        text = bytes(self.buf).lstrip(b" \t")
        if not text:
            self.mode = -1
            return
        c = text[0] & 0xDF  # upper case
        self.mode = echo_mode(c - 0x40) if 0x41 <= c <= 0x5A else None

    def feed(self, data: bytes, echo_mode: Callable[[int], int | None]) -> tuple[bytes, list[str]]:
        """(echo bytes, complete lines). ``echo_mode(address)`` is global parameter 67 of
        the module with that address, None when the line has none."""
        echo = bytearray()
        lines: list[str] = []
        for b in data:
            if b == 0x0D:
                if self.mode == -1:
                    self._decide(echo_mode)
                mode = self.mode
                text = self.buf.decode("ascii", "replace")
                if mode is not None and mode >= 0:
                    if mode & 0x30 == 0:
                        echo += b"\r"
                    elif mode & 0x30 == 0x10:
                        echo += self.buf + b"\r"
                lines.append(text)
                self.buf.clear()
                self.mode = -1
            elif b == 0x0A:
                continue
            elif b in (0x08, 0x7F):
                if self.buf:
                    self.buf.pop()
                    if self._per_char():
                        echo += b"\b \b"
                    if not bytes(self.buf).strip(b" \t"):
                        self.mode = -1  # the address character is gone: undecided
            elif len(self.buf) < MAX_LINE:
                self.buf.append(b)
                if self.mode == -1:
                    self._decide(echo_mode)
                    if self._per_char():
                        echo += self.buf  # the address character and the spaces before
                elif self._per_char():
                    echo.append(b)
        return bytes(echo), lines

    def _per_char(self) -> bool:
        return self.mode is not None and self.mode >= 0 and self.mode & 0x30 == 0
