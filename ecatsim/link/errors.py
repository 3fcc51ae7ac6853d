"""Link errors: one line naming the problem and the fix."""

from __future__ import annotations


class LinkError(ValueError):
    """Opening or using a link failed in a way the user can fix."""
