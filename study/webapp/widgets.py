"""Which form widget shows a codebook response type, and the check that an instrument can be shown at all."""
from __future__ import annotations

from study.common.errors import UserError
from study.folder.instrument import is_scaled


def widget(response_type: str) -> str:
    """The form widget of a codebook response type: 'scale' (k radios), 'choice', 'number' or 'text'.

    A type the form cannot show raises UserError: a question without inputs must never be offered."""
    if is_scaled(response_type):
        return "scale"
    if response_type in ("choice", "number", "text"):
        return response_type
    raise UserError(f"the web form cannot show response type {response_type!r}")


def check_renderable(ins) -> None:
    """UserError naming the first item of `ins` the web form cannot show (checked before the server starts)."""
    for item, kind in ins.items["response_type"].items():
        try:
            widget(kind)
        except UserError as exc:
            raise UserError(f"instrument {ins.name}, item {item}: {exc}") from None
