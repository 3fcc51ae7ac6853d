"""esc layer; see docs/architecture.md."""
