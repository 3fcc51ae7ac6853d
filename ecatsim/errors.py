"""Errors a user can cause: shown as one line naming what is wrong and the fix."""

from __future__ import annotations


class UserError(Exception):
    """A configuration, file, permission or interface problem the user can fix."""
