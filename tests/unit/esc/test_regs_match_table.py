"""``esc/regs.py`` names only registers that the register table holds, at their address.

The table (``ecatsim/spec/registers.yaml``) is the one source of access rights, reset
values and side effects; ``regs.py`` gives the code names for its addresses. This test
ties the two: every address constant is the first byte of a row, and the FMMU/SM strides
are the table's repeat strides. Ref: TMC8460 §4 Table 11, §5.48-5.49.
"""

from __future__ import annotations

import ast
from pathlib import Path

from ecatsim.esc import regs
from ecatsim.spec.tables import load_registers

SRC = Path(regs.__file__).with_suffix(".py")


def _address_constants() -> dict[str, int]:
    """The constants of regs.py's register block: everything before ``PDRAM_START``."""
    out: dict[str, int] = {}
    for node in ast.parse(SRC.read_text()).body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            name = node.targets[0].id
            if name == "PDRAM_START":
                break
            if not name.endswith("_STRIDE"):
                out[name] = getattr(regs, name)
    return out


def test_every_address_constant_starts_a_row() -> None:
    starts = {r.addr: r.name for r in load_registers()}
    consts = _address_constants()
    assert len(consts) >= 88  # the reader found the block, not an empty prefix of it
    wrong = {n: hex(a) for n, a in consts.items() if a not in starts}
    assert not wrong, f"regs.py constants with no register row at their address: {wrong}"


def test_strides_are_the_tables_repeats() -> None:
    rows = load_registers()
    fmmu = [r.addr for r in rows if r.name.endswith("_logical_start")]
    sm = [r.addr for r in rows if r.name.endswith("_physical_start") and r.name.startswith("sm")]
    assert fmmu[0] == regs.FMMU_BASE and fmmu[1] - fmmu[0] == regs.FMMU_STRIDE
    assert len(fmmu) == regs.N_FMMU
    assert sm[0] == regs.SM_BASE and sm[1] - sm[0] == regs.SM_STRIDE
    assert len(sm) == regs.N_SM
