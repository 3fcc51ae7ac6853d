"""SII EEPROM image files: load, and save atomically (temp file, fsync, rename).

A crash at any moment leaves either the old or the new image, never a torn one.
"""

from __future__ import annotations

from pathlib import Path

from ecatsim.files import atomic_write
from ecatsim.sii.image import SiiError, parse_image


class EepromStore:
    """Reading and atomically writing ``.bin`` SII images."""

    @staticmethod
    def load(path: Path) -> bytearray:
        """Read an image; SiiError (one line naming the file and what is wrong) where
        ``ecatsim eeprom show`` would reject it: too short for the header, an odd size,
        categories that run past the end or no end marker."""
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise SiiError(f"{path}: cannot read the EEPROM image ({exc.strerror})") from exc
        try:
            parse_image(data)  # what 'ecatsim eeprom show' accepts (decision O3)
        except SiiError as exc:
            raise SiiError(
                f"{path}: not an SII EEPROM image: {exc}; rebuild it with "
                "'ecatsim eeprom build', or remove it and a new one is made"
            ) from None
        return bytearray(data)

    @staticmethod
    def save(path: Path, data: bytes) -> None:
        """Write ``data`` to ``path`` atomically and durably."""
        atomic_write(path, data)
