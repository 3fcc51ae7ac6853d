"""device layer; see docs/architecture.md."""
