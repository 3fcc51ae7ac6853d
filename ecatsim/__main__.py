"""``python -m ecatsim`` runs the CLI."""

from __future__ import annotations

from ecatsim.cli import main

if __name__ == "__main__":
    main()
