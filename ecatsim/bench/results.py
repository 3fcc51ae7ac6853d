"""Where a benchmark run is recorded: ``<dir>/<name>-<time>.json`` (``--results``,
bench/results under the current directory unless given)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

DEFAULT_DIR = Path("bench") / "results"


def write(results_dir: Path, name: str, data: dict[str, Any]) -> Path:
    """Write ``data`` as ``results_dir/name-YYYYmmdd-HHMMSS.json`` and print its path."""
    results_dir.mkdir(parents=True, exist_ok=True)
    path = results_dir / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.write_text(json.dumps(data, indent=2) + "\n")
    shown = path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path
    print(f"written {shown}")
    return path
