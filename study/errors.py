"""Errors that carry a one-line reason for the user. The CLI prints the message and exits non-zero."""
from __future__ import annotations


class UserError(ValueError):
    """Bad input or a refused operation; the message is shown to the user as is (one line)."""
