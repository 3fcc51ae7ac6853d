"""slave layer; see docs/architecture.md."""
