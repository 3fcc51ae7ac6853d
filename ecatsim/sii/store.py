"""SII EEPROM image files: load, and save atomically (temp file, fsync, rename).

A crash at any moment leaves either the old or the new image, never a torn one.
"""

from __future__ import annotations

from pathlib import Path

from ecatsim.files import atomic_write
from ecatsim.sii.image import SiiError


class EepromStore:
    """Reading and atomically writing ``.bin`` SII images."""

    @staticmethod
    def load(path: Path) -> bytearray:
        """Read an image; SiiError (one line naming the file) if unusable."""
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise SiiError(f"{path}: cannot read the EEPROM image ({exc.strerror})") from exc
        if len(data) < 16 or len(data) % 2:
            raise SiiError(
                f"{path}: {len(data)} bytes is not an SII image (need an even size >= 16); "
                "rebuild it with 'ecatsim eeprom build'"
            )
        return bytearray(data)

    @staticmethod
    def save(path: Path, data: bytes) -> None:
        """Write ``data`` to ``path`` atomically and durably."""
        atomic_write(path, data)
