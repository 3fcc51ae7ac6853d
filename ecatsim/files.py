"""Atomic file writes: temp file in the same directory, fsync, rename, fsync the directory.

A crash at any moment leaves either the old or the new file, never a torn one. The file
gets the permissions a plain ``open(path, "w")`` would give it: a replaced file keeps its
mode, a new one gets 0666 less the umask (the temp file alone would leave it 0600).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import IO

from ecatsim.errors import UserError


def current_umask() -> int:
    """The process umask (read by setting it and setting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(path: Path) -> int:
    try:
        return path.stat().st_mode & 0o7777
    except FileNotFoundError:
        return 0o666 & ~current_umask()


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically and durably."""
    path = Path(path)
    d = path.parent if str(path.parent) else Path(".")
    mode = _mode_for(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=d)
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    dfd = os.open(d, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


def write_output(path: Path, data: bytes, option: str = "-o") -> None:
    """Write a command's output file atomically; a path that cannot be written is one
    line naming the option, the path and the fix (no traceback, no partial file)."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise UserError(
            f"{option} {path}: the directory {parent} {what}: create it first or write elsewhere"
        )
    if path.is_dir():
        raise UserError(f"{option} {path}: is a directory: give a file name")
    try:
        atomic_write(path, data)
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot write ({exc.strerror or exc})") from exc


def open_trace(path: Path, option: str = "--trace") -> IO[str]:
    """A CSV trace file opened for writing (the caller closes it); a path that cannot be
    written is one line naming the option and the path."""
    try:
        return open(path, "w", newline="")
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot write ({exc.strerror})") from exc
