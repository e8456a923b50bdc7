"""Optional dependencies, installed with an extra of pyproject.toml (``pip install pedas-study[EXTRA]``)."""
from __future__ import annotations

import importlib.util

from study.common.errors import UserError


def require(module: str, extra: str, purpose: str) -> None:
    """Nothing if `module` can be imported, else UserError "<purpose> needs <module>: install pedas-study[<extra>]"."""
    if importlib.util.find_spec(module) is None:
        raise UserError(f"{purpose} needs {module}: install pedas-study[{extra}]")
