"""Atomic writes give files the permissions a plain write would."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from ecatsim.files import atomic_write


@pytest.fixture
def umask_027() -> Iterator[None]:
    old = os.umask(0o027)
    yield
    os.umask(old)


def test_a_new_file_gets_0666_less_the_umask(tmp_path: Path, umask_027: None) -> None:
    p = tmp_path / "out.bin"
    atomic_write(p, b"abc")
    assert p.read_bytes() == b"abc"
    assert stat.S_IMODE(p.stat().st_mode) == 0o640
    assert os.umask(0o027) == 0o027  # the umask is left as it was


def test_a_replaced_file_keeps_its_mode(tmp_path: Path, umask_027: None) -> None:
    p = tmp_path / "out.bin"
    p.write_bytes(b"old")
    p.chmod(0o604)
    atomic_write(p, b"new")
    assert (p.read_bytes(), stat.S_IMODE(p.stat().st_mode)) == (b"new", 0o604)
    assert [q.name for q in tmp_path.iterdir()] == ["out.bin"]  # no temp file left


def test_cli_esi_export_honours_the_umask(tmp_path: Path, umask_027: None) -> None:
    from click.testing import CliRunner

    from ecatsim.cli import cli

    out = tmp_path / "drive.xml"
    r = CliRunner().invoke(cli, ["esi", "export", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert stat.S_IMODE(out.stat().st_mode) == 0o640
