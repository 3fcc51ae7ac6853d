"""ruff and mypy (configured in pyproject.toml) are part of the test suite."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=600
    )


def test_ruff_check() -> None:
    r = _run("ruff", "check", "ecatsim", "tests", "tools")
    assert r.returncode == 0, r.stdout + r.stderr


def test_ruff_format() -> None:
    r = _run("ruff", "format", "--check", "ecatsim", "tests", "tools")
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_strict() -> None:
    """The package, the tests and the tools (``files`` in pyproject.toml)."""
    r = _run("mypy")
    assert r.returncode == 0, r.stdout + r.stderr
