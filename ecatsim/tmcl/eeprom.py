"""The configuration EEPROM of the emulated modules, kept in one JSON file (``--eeprom``).

What STAP, STGP, SGP of bank 0, stored coordinates and downloaded programs write survives
a restart; everything else comes back at its factory default. The file is rewritten
atomically on every store, so a crash leaves the old or the new contents.

Ref: TMCM-1311 TMCL firmware manual §5.7.7 (STAP), §5.7.11 (STGP), §10.1 (bank 0 lives in
the EEPROM), §10.3 (user variables), §4.3 (program memory).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ecatsim.errors import UserError
from ecatsim.files import atomic_write

FORMAT = "ecatsim-tmcl-eeprom/1"


class Section:
    """One module's part of the EEPROM."""

    def __init__(self, data: dict[str, Any], save: Any) -> None:
        self._data = data
        self._save = save

    def _map(self, key: str) -> dict[str, int]:
        out: dict[str, int] = self._data.setdefault(key, {})
        return out

    def axis(self) -> dict[int, int]:
        return {int(k): int(v) for k, v in self._map("axis").items()}

    def globals(self) -> dict[tuple[int, int], int]:
        out: dict[tuple[int, int], int] = {}
        for k, v in self._map("global").items():
            bank, _, num = k.partition(".")
            out[(int(bank), int(num))] = int(v)
        return out

    def coords(self) -> dict[int, int]:
        return {int(k): int(v) for k, v in self._map("coords").items()}

    def program(self) -> list[tuple[int, int, int, int]]:
        prog = self._data.get("program", [])
        return [(int(a), int(b), int(c), int(d)) for a, b, c, d in prog]

    def put_axis(self, number: int, value: int) -> None:
        self._map("axis")[str(number)] = value
        self._save()

    def put_global(self, bank: int, number: int, value: int) -> None:
        self._map("global")[f"{bank}.{number}"] = value
        self._save()

    def put_coord(self, number: int, value: int) -> None:
        self._map("coords")[str(number)] = value
        self._save()

    def put_program(self, words: list[tuple[int, int, int, int]]) -> None:
        self._data["program"] = [list(w) for w in words]
        self._save()

    def clear(self) -> None:
        """Factory defaults (command 137, or a wrong EEPROM magic at power-up)."""
        self._data.clear()
        self._save()


class Eeprom:
    """All modules' EEPROM sections; in memory only when no file is given."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.writes = 0
        self._data: dict[str, Any] = {"format": FORMAT, "modules": {}}
        if path is not None and path.exists():
            try:
                data = json.loads(path.read_text())
            except (OSError, ValueError) as exc:
                raise UserError(
                    f"--eeprom {path}: not a TMCL EEPROM file ({exc}); "
                    "remove it to start from factory defaults"
                ) from exc
            if not isinstance(data, dict) or data.get("format") != FORMAT:
                raise UserError(
                    f"--eeprom {path}: format is not {FORMAT!r}; remove it to start from "
                    "factory defaults"
                )
            self._data = data

    def section(self, index: int) -> Section:
        modules: dict[str, Any] = self._data["modules"]
        return Section(modules.setdefault(str(index), {}), self.save)

    def save(self) -> None:
        self.writes += 1
        if self.path is not None:
            atomic_write(self.path, json.dumps(self._data, indent=1, sort_keys=True).encode())
