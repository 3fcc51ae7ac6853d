"""The floor: a minimal C responder (package data ``echo.c``) built with the system
compiler, against which the daemon's round trip is compared.

Ref: docs/performance.md "How to measure".
"""

from __future__ import annotations

import shutil
import subprocess
from importlib import resources
from pathlib import Path

from ecatsim.errors import UserError

SOURCE = "echo.c"


def c_source(name: str) -> str:
    """The C source ``name`` shipped with the package (the floor, the host probe)."""
    return resources.files("ecatsim.bench").joinpath(name).read_text()


def echo_source() -> str:
    """The C source of the floor, from the installed package."""
    return c_source(SOURCE)


def build_c(name: str, out: Path) -> Path:
    """Compile the package's C source ``name`` to ``out`` with ``cc -O2``; a missing
    compiler is one line."""
    cc = shutil.which("cc")
    if cc is None:
        raise UserError("ecatsim bench builds its C programs with 'cc': install a C compiler")
    subprocess.run([cc, "-O2", "-o", str(out), "-x", "c", "-"], input=c_source(name).encode(),
                   check=True)  # fmt: skip
    return out


def build_echo(out: Path) -> Path:
    """Compile the floor to ``out``."""
    return build_c(SOURCE, out)


def echo_command(ns: str, iface: str, echo: Path, mode: str, pin: list[str]) -> list[str]:
    """The command that runs the floor on ``iface`` in namespace ``ns`` (``pin``: a
    ``taskset`` prefix or nothing), ``mode`` "block" or "busy" as the daemon waits."""
    return ["ip", "netns", "exec", ns, *pin, str(echo), iface, mode]
