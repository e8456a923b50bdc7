"""The shipped standard instruments (``studies/instruments/``) and their inclusion into a study by reference.

Each shipped instrument is two plain files: ``<name>.csv``, a codebook (study/folder/instrument.py), and ``<name>.toml``
with ``[instrument]`` name, version, title and source (the publication its items and scoring follow) and its
``[[scores]]`` (study/folder/scores.py). A study includes one by name in its study.toml::

    [instrument]
    include = ["sus", "nasa_tlx_raw"]

:func:`included_files` reads the included files when the study folder is read, keyed by their repository path
(``studies/instruments/sus.csv``), so the store keeps their texts with the study's own files: a stored study never
reads the library again, and a changed library file is a changed study (a new version at ``init --study``).
Each included codebook is an instrument of the study named ``<[instrument] name>_v<version>`` of its TOML file.
This module imports nothing heavy: it runs whenever a study folder is read.
"""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

LIBRARY_KEY = "studies/instruments"   # the key prefix of an included file: its path in the repository
LIBRARY = Path(__file__).resolve().parents[2] / LIBRARY_KEY


def shipped() -> list[str]:
    """Names of the shipped instruments (a codebook with its TOML file), sorted."""
    return sorted(p.stem for p in LIBRARY.glob("*.csv") if p.with_suffix(".toml").is_file())


def includes(settings: dict[str, Any]) -> list[str]:
    """The names a study's ``[instrument] include`` lists (text entries only; the check reports the rest)."""
    inst = settings.get("instrument", {})
    raw = inst.get("include", []) if isinstance(inst, dict) else []
    raw = [raw] if isinstance(raw, str) else raw
    names = [r for r in raw if isinstance(r, str)] if isinstance(raw, list) else []
    return list(dict.fromkeys(names))   # a name listed twice is included once (the check reports it)


def paths(name: str) -> tuple[str, str]:
    """(codebook key, TOML key) of the shipped instrument `name` in a study's files."""
    return f"{LIBRARY_KEY}/{name}.csv", f"{LIBRARY_KEY}/{name}.toml"


def is_library_key(rel: str) -> bool:
    return rel.startswith(LIBRARY_KEY + "/")


def included_files(data: dict[str, Any]) -> dict[str, str]:
    """{key: text} of the codebook and TOML file of every shipped instrument the parsed study.toml `data` includes;
    a name that is not shipped is left out here (the study check names it)."""
    out: dict[str, str] = {}
    known = set(shipped())
    for name in includes(data):
        if name in known:
            for key in paths(name):
                out[key] = (LIBRARY.parent.parent / key).read_text(encoding="utf-8")
    return out


def meta(files: dict[str, str], name: str) -> dict[str, Any]:
    """The ``[instrument]`` table of an included instrument's TOML text ({} when absent or unreadable)."""
    try:
        data = tomllib.loads(files.get(paths(name)[1], ""))
    except tomllib.TOMLDecodeError:
        return {}
    inst = data.get("instrument", {})
    return inst if isinstance(inst, dict) else {}


def included_instruments(settings: dict[str, Any], files: dict[str, str]) -> list[tuple[str, str]]:
    """(stored instrument name, codebook key) of each included instrument present in `files`, in include order:
    ``<[instrument] name>_v<version>`` of its TOML file (default: the file's name, version 1)."""
    out = []
    for name in includes(settings):
        csv_key = paths(name)[0]
        if csv_key in files:
            m = meta(files, name)
            out.append((f"{m.get('name', name)}_v{m.get('version', 1)}", csv_key))
    return out
