"""sii layer; see docs/architecture.md."""
