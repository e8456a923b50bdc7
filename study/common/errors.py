"""Errors that carry a one-line reason for the user. The CLI prints the message and exits non-zero."""
from __future__ import annotations


class UserError(ValueError):
    """Bad input or a refused operation; the message is shown to the user as is (one line)."""


def check_choice(name: str, value, allowed: tuple[str, ...]):
    """`value` if it is one of `allowed`, else UserError "<name> must be one of a|b|c, not 'x'"."""
    if value not in allowed:
        raise UserError(f"{name} must be one of {'|'.join(allowed)}, not {value!r}")
    return value


def check_name(kind: str, value, known) -> None:
    """Refuse a `kind` (protocol, instrument) given as a path instead of a name the study declares: the study's
    files are chosen by name from the stored definition, never read from a path."""
    if isinstance(value, str) and ("/" in value or "\\" in value or ".." in value):
        raise UserError(f"{kind} {value!r} is a path; give the name of one the study declares ({', '.join(known)})")


def shown(path) -> str:
    """A file name for a message: the path as the user gave it (not only its last part), control characters
    escaped (a stray CR from a file list shows as ``\\r``, a tab as ``\\t``, others as ``\\xNN``)."""
    return escaped(str(path))


def escaped(text: str) -> str:
    """`text` with its control characters (C0, DEL) written as escapes, so that it stays one readable line."""
    return "".join(_ESCAPES.get(c, c) for c in text)


_ESCAPES = {**{chr(i): f"\\x{i:02x}" for i in (*range(32), 127)}, "\t": "\\t", "\r": "\\r", "\n": "\\n"}


def split_names(text: str | None) -> tuple[str, ...]:
    """The names of a comma-separated option value (``--ignore-columns a,b``), stripped, empty ones left out."""
    return tuple(n.strip() for n in (text or "").split(",") if n.strip())
