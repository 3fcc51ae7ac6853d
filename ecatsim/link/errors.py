"""Link errors: one line naming the problem and the fix.

Ref: docs/architecture.md (the CLI prints a LinkError as ``ecatsim: error: ...``).
"""

from __future__ import annotations


class LinkError(ValueError):
    """Opening or using a link failed in a way the user can fix."""
