"""--trace CSV rows and `ecatsim plot` output."""

from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

from ecatsim.cli import cli
from ecatsim.device.trace import COLUMNS, TraceWriter
from tests.unit.device.test_drive import MS, command, enable, make


def test_trace_rows_and_plot(tmp_path: Path) -> None:
    d, _ = make()
    path = tmp_path / "t.csv"
    w = TraceWriter(path)
    d.tracer = lambda now, row: w.row(now, 0, row)
    t = enable(d, 3)
    for i in range(1, 200):
        command(d, t + i * MS, 0x0F, x60FF=800)
    w.close()
    rows = list(csv.DictReader(path.open()))
    assert tuple(rows[0]) == COLUMNS
    assert rows[-1]["state"] == "OPERATION_ENABLED" and rows[-1]["mode"] == "3"
    assert int(rows[-1]["target_velocity"]) == 800
    assert 0 < int(rows[-1]["velocity"]) <= 800
    out = tmp_path / "p.png"
    r = CliRunner().invoke(cli, ["plot", str(path), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    r = CliRunner().invoke(cli, ["plot", str(path), "-o", str(out), "--slave", "3"])
    assert r.exit_code != 0 and "no rows for slave 3" in str(r.exception)


def test_plot_of_a_file_that_is_no_trace_says_why(tmp_path: Path) -> None:
    other = tmp_path / "other.csv"
    other.write_text("a,b\n1,2\n")
    binary = tmp_path / "image.bin"
    binary.write_bytes(bytes(range(128, 256)))
    hint = "; write one with 'ecatsim run --trace FILE.csv'"
    for path, why in (
        (other, "columns time_s, slave, controlword missing"),
        (binary, "binary, not CSV text"),
    ):
        r = CliRunner().invoke(cli, ["plot", str(path), "-o", str(tmp_path / "p.png")])
        assert str(r.exception) == f"{path}: not an ecatsim trace ({why}){hint}"


def test_eeprom_show_of_junk_says_it_is_no_sii_image(tmp_path: Path) -> None:
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(16)) + b"\xff" * 112 + b"\x01\x00\xff\x7f")
    r = CliRunner().invoke(cli, ["eeprom", "show", str(junk)])
    assert str(r.exception) == (
        f"{junk}: not an SII EEPROM image: category 1 at word 0x0040 (32767 words) runs past "
        "the end; and the header checksum (word 7) is 0x0E, not 0xE0"
    )


def test_state_marks_merge_a_quick_enable_sequence() -> None:
    from ecatsim.device.trace import mode_spans, state_marks

    states = ["SWITCH_ON_DISABLED"] * 2 + ["READY_TO_SWITCH_ON", "SWITCHED_ON"]
    states += ["OPERATION_ENABLED"] * 96 + ["READY_TO_SWITCH_ON"]
    modes = ["0"] + ["1"] * 50 + ["8"] * 50
    rows = [{"state": s, "mode": m} for s, m in zip(states, modes, strict=True)]
    t = [i / 100 for i in range(len(rows))]
    assert state_marks(t, rows) == [(0.02, "SOD→RTSO→SO→OE"), (1.0, "OE→RTSO")]
    assert mode_spans(t, rows) == [(0.01, 0.51, "pp"), (0.51, 1.0, "csp")]
