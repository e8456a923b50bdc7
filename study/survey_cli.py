"""CLI commands of this part (see `study.cli` for the registration contract)."""
from __future__ import annotations


def register(cli) -> None:
    """Add this module's commands to the `pedas-study` parser."""
