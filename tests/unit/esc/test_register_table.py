"""The register table (data) and the ESC hooks (code) agree; identity values are exact.

Ref: TMC8460 §4 Table 11, §5.
"""

from __future__ import annotations

import itertools

import pytest

from ecatsim.esc.context import FrameContext
from ecatsim.esc.core import Esc
from ecatsim.esc.dispatch import PASSIVE_SIDE_EFFECTS, compile_tables
from ecatsim.esc.regs import DC_SYSTEM_TIME
from ecatsim.esc.units import hook_names, tables, unit_classes
from ecatsim.spec.tables import UNITS, SpecError, load_registers, parse_registers


def test_every_side_effect_in_the_table_has_a_hook_and_back() -> None:
    used = {r.side_effect for r in load_registers() if r.side_effect}
    hooks = hook_names()
    assert used - hooks - PASSIVE_SIDE_EFFECTS == set()
    assert hooks - used == set()
    assert PASSIVE_SIDE_EFFECTS - used == set()
    assert hooks & PASSIVE_SIDE_EFFECTS == set()
    assert {u.partition(".")[0] for u in used} <= UNITS


@pytest.mark.parametrize("size", [4, 8])
def test_the_frmw_system_time_read_is_the_register_read(size: int) -> None:
    """Esc.ecat_read_system_time (the FRMW of every DC cycle) returns the bytes and the
    WKC increment that ecat_read of 0x0910 does, at several frame times, with an offset
    and a drifting clock: the same hook, the same memory."""
    escs = [
        Esc(0, FrameContext(), bytearray(b"\xff" * 256), dc_start_ns=123_456_789, dc_drift_ppm=d)
        for d in (37.5, 37.5)
    ]
    for e in escs:
        e.mem[0x0920:0x0928] = (0xFFFF_FFFF_0000_1234).to_bytes(8, "little")
    fast, slow = escs
    for t in (0, 1, 999_999, 10**9 + 7, 2**40 + 3):
        fast.ctx.t_ns = slow.ctx.t_ns = t
        a, b = bytearray(size), bytearray(size)
        assert (
            fast.ecat_read_system_time(memoryview(a))
            == slow.ecat_read(DC_SYSTEM_TIME, memoryview(b))
            == 1
        )
        assert a == b
        assert a != bytes(size) or t == 0
        assert fast.mem == slow.mem


def test_every_row_cites_the_datasheet_and_rows_do_not_overlap() -> None:
    rows = load_registers()
    assert all(r.source.startswith("TMC8460 §") for r in rows)
    for a, b in itertools.pairwise(rows):
        assert a.addr + a.size <= b.addr


def test_identity_and_repeats() -> None:
    by = {r.name: r for r in load_registers()}
    assert by["type"].reset == 0xD0
    assert by["revision"].reset == 0x60
    assert by["esc_features"].reset == 0x01CC
    assert by["product_id"].reset == 0x01008460
    assert by["vendor_id"].reset == 0x286
    assert by["sm5_activate"].addr == 0x082E
    assert by["fmmu5_activate"].addr == 0x065C
    assert "sm6_activate" not in by and "fmmu6_activate" not in by
    assert by["dl_control"].ecat_wmask == 0x01FFFF03
    assert not by["write_register_protection"].available


def test_write_masks_compiled() -> None:
    t = tables()
    assert t.ecat_wmask[0x0000] == 0  # type: read-only
    assert t.ecat_wmask[0x0021] == 0  # not available on the TMC8460-BI
    assert t.ecat_wmask[0x0010] == 0xFF
    assert t.pdi_wmask[0x0010] == 0  # station address: PDI read-only
    assert t.pdi_wmask[0x0012] == 0xFF  # alias: PDI writes it


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("registers:\n  - {addr: 0x10, size: 2, name: a, ecat: rw, pdi: r, source: x}\n"
         "  - {addr: 0x11, size: 1, name: b, ecat: r, pdi: r, source: x}\n", "a overlaps b"),
        ("registers:\n  - {addr: 0x10, size: 1, name: a, ecat: rx, pdi: r, source: x}\n", "(a)"),
        ("registers:\n  - {addr: 0x10, size: 1, name: a, ecat: r, pdi: r}\n", "missing 'source'"),
        ("registers:\n  - {addr: 0x10, size: 1, name: a, ecat: r, pdi: r, source: x,"
         " side_effect: magic}\n", "unknown side_effect"),
        ("registers:\n  - {addr: 0x10, size: 1, name: a, ecat: rw, pdi: r, source: x,"
         " ecat_wmask: 0x100}\n", "ecat_wmask"),
    ],
)  # fmt: skip
def test_malformed_rows_are_named(text: str, fragment: str) -> None:
    with pytest.raises(SpecError) as e:
        parse_registers(text)
    assert fragment in str(e.value)


def test_an_ecat_write_hook_runs_on_every_write_or_on_a_change_not_both() -> None:
    """``_ew_<name>`` and ``_ec_<name>`` of one unit would both claim the register's ECAT
    write: the dispatch refuses the pair (decision U1)."""

    def hook(unit: object, ra: int, rs: int, old: bytes) -> None:
        pass  # pragma: no cover - never called

    classes = dict(unit_classes())
    classes["dc"] = type("Dc", (), {"_ew_activation": hook, "_ec_activation": hook})
    with pytest.raises(SpecError, match=r"dc\.activation"):
        compile_tables(classes)
