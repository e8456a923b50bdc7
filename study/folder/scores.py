"""Declared scores of a study's instruments: which items, which reversed, which weights, how aggregated, how
transformed (docs/survey.md, "Scores"). Parsed and checked here; computed by analysis/survey/scores.py.

A score is a ``[[scores]]`` table, in study.toml (for the study's own codebooks) or in the TOML file of a shipped
instrument the study includes (study/folder/instrument_library.py)::

    [[scores]]
    name = "SUS"                      # letters, digits, _; unique in the study
    label = "System Usability Scale"  # optional
    instrument = "sus"                # study.toml only: the stored name with or without _vN; default: the first
    items = ["SUS1", "SUS2", ...]     # scaled items of that instrument
    reversed = ["SUS2", "SUS4", ...]  # x -> min + max - x on each item's own scale, before weighting
    weights = [2, 1, ...]             # optional fixed weight per item (same count as items), default 1
    weights_from = ["W_MD", ...]      # or: per participant, the answer to these items (same count as items)
    weights_total = 15                # with weights_from: the weights must add up to this (else refused)
    aggregate = "sum"                 # sum = sum_i w_i x_i ; mean = sum_i w_i x_i / sum_i w_i
    multiply = 2.5                    # value = aggregate * multiply + add (defaults 1 and 0)
    add = -25

A score is missing (NaN) for a participant who left any of its items or weights unanswered: no prorating.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from typing import Any

from study.common.file_checks import register_file_check
from study.common.problems import Problems, StudyError
from study.common.toml_lines import line_of
from study.folder.instrument import Instrument, is_scaled
from study.folder.instrument_library import (
    included_instruments,
    includes,
    paths,
    shipped,
)

STUDY_FILE = "study.toml"
NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
KEYS = ("name", "label", "instrument", "items", "reversed", "weights", "weights_from", "weights_total",
        "aggregate", "multiply", "add")
AGGREGATES = ("sum", "mean")


@dataclass(frozen=True)
class ScoreSpec:
    """One declared score of one instrument (the stored name, e.g. ``sus_v1``); see the module docstring."""

    name: str
    instrument: str
    items: tuple[str, ...]
    aggregate: str
    reversed: tuple[str, ...] = ()
    weights: tuple[float, ...] | None = None
    weights_from: tuple[str, ...] | None = None
    weights_total: float | None = None
    multiply: float = 1.0
    add: float = 0.0
    label: str = ""
    file: str = STUDY_FILE


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")


def _names(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _stem(name: str) -> str:
    return re.sub(r"_v\d+$", "", name)


def _parse_table(raw: Any, k: int, rel: str, text: str, seen: dict, problems: Problems,
                 fixed_instrument: str | None, instruments: dict) -> ScoreSpec | None:
    """One ``[[scores]]`` table -> ScoreSpec, or None with its problems added (one line each)."""
    def where(key: str) -> int | None:
        return line_of(text, key, "scores", k) if key else line_of(text, "", "scores", k)

    fld = f"scores[{k}]"
    if not isinstance(raw, dict):
        problems.add(rel, where(""), fld, "must be a table")
        return None
    ok = True
    for key in raw:
        if key not in KEYS or (key == "instrument" and fixed_instrument):
            problems.add(rel, where(key), f"{fld}.{key}", f"unknown key (known: {', '.join(KEYS)})")
            ok = False
    name = raw.get("name")
    if not isinstance(name, str) or not NAME.match(name):
        problems.add(rel, where("name"), f"{fld}.name", "needs a name of letters, digits and _, starting with a letter")
        return None
    fld = f"scores.{name}"
    if name in seen:
        problems.add(rel, where("name"), f"{fld}.name", f"score {name!r} declared twice (also in {seen[name]})")
        ok = False
    seen.setdefault(name, rel)
    # which instrument
    ins_name = fixed_instrument
    if ins_name is None:
        want = raw.get("instrument")
        if want is None:
            ins_name = next(iter(instruments), None)
        elif not isinstance(want, str):
            problems.add(rel, where("instrument"), f"{fld}.instrument", "must be an instrument name")
            return None
        else:
            hits = [n for n in instruments if want in (n, _stem(n))]
            if not hits:
                problems.add(rel, where("instrument"), f"{fld}.instrument",
                             f"{want!r} is not an instrument of the study ({', '.join(instruments) or 'none'})")
                return None
            ins_name = hits[0]
    if ins_name is None:
        problems.add(rel, where("name"), fld, "the study declares no instrument to score")
        return None
    instrument = instruments.get(ins_name)
    items = raw.get("items")
    if not _names(items) or not items:
        problems.add(rel, where("items"), f"{fld}.items", "must be a non-empty list of item ids")
        return None
    known = instrument.items if instrument is not None else None

    def check_items(key: str, its: list[str], numeric_ok: bool) -> bool:
        good = True
        for it in its:
            if known is None:
                continue
            if it not in known.index:
                problems.add(rel, where(key), f"{fld}.{key}", f"{it!r} is not an item of instrument {ins_name}")
                good = False
                continue
            kind = str(known.loc[it, "response_type"])
            if not (is_scaled(kind) or (numeric_ok and kind in ("number", "choice"))):
                problems.add(rel, where(key), f"{fld}.{key}",
                             f"{it!r} is a {kind} item; a score takes scaled items (likert, semantic, slider)"
                             + (" or numbers" if numeric_ok else ""))
                good = False
        dup = sorted({it for it in its if its.count(it) > 1})
        if dup:
            problems.add(rel, where(key), f"{fld}.{key}", f"{', '.join(dup)} listed twice")
            good = False
        return good

    ok = check_items("items", items, False) and ok
    rev = raw.get("reversed", [])
    if not _names(rev):
        problems.add(rel, where("reversed"), f"{fld}.reversed", "must be a list of item ids")
        ok, rev = False, []
    for it in rev:
        if it not in items:
            problems.add(rel, where("reversed"), f"{fld}.reversed", f"reversed item {it!r} is not among the "
                                                                    f"score's items")
            ok = False
    weights, wfrom, wtotal = raw.get("weights"), raw.get("weights_from"), raw.get("weights_total")
    if weights is not None and wfrom is not None:
        problems.add(rel, where("weights_from"), f"{fld}.weights_from", "give weights or weights_from, not both")
        ok = False
    if weights is not None:
        if not isinstance(weights, list) or not all(_number(w) for w in weights):
            problems.add(rel, where("weights"), f"{fld}.weights", "must be a list of numbers")
            ok = False
        elif len(weights) != len(items):
            problems.add(rel, where("weights"), f"{fld}.weights", f"{len(weights)} weights for {len(items)} items")
            ok = False
    if wfrom is not None:
        if not _names(wfrom):
            problems.add(rel, where("weights_from"), f"{fld}.weights_from", "must be a list of item ids")
            ok = False
        elif len(wfrom) != len(items):
            problems.add(rel, where("weights_from"), f"{fld}.weights_from",
                         f"{len(wfrom)} weight items for {len(items)} items")
            ok = False
        else:
            ok = check_items("weights_from", wfrom, True) and ok
    if wtotal is not None and (not _number(wtotal) or wfrom is None):
        problems.add(rel, where("weights_total"), f"{fld}.weights_total",
                     "a number, with weights_from (the total each participant's weights must reach)")
        ok = False
    aggregate = raw.get("aggregate")
    if aggregate not in AGGREGATES:
        problems.add(rel, where("aggregate"), f"{fld}.aggregate", f"{aggregate!r} is not {' | '.join(AGGREGATES)}")
        ok = False
    for key, default in (("multiply", 1), ("add", 0)):
        if not _number(raw.get(key, default)):
            problems.add(rel, where(key), f"{fld}.{key}", f"{raw[key]!r} is not a number")
            ok = False
    if aggregate == "mean" and weights is not None and _number(sum(weights) if isinstance(weights, list)
                                                                and all(_number(w) for w in weights) else None) \
            and sum(weights) == 0:
        problems.add(rel, where("weights"), f"{fld}.weights", "weights adding up to 0 leave the mean undefined")
        ok = False
    label = raw.get("label", "")
    if not isinstance(label, str):
        problems.add(rel, where("label"), f"{fld}.label", "must be text")
        ok = False
    if not ok:
        return None
    return ScoreSpec(name=name, instrument=ins_name, items=tuple(items), aggregate=aggregate, reversed=tuple(rev),
                     weights=tuple(float(w) for w in weights) if weights is not None else None,
                     weights_from=tuple(wfrom) if wfrom is not None else None,
                     weights_total=float(wtotal) if wtotal is not None else None,
                     multiply=float(raw.get("multiply", 1)), add=float(raw.get("add", 0)), label=label, file=rel)


def _instruments(study) -> dict:
    """{stored name: Instrument, or None for a codebook with problems of its own (reported by its check)}."""
    return {name: Instrument.from_csv(name, study.files[rel], rel, problems=Problems())
            for name, rel in study.instrument_files if rel in study.files}


def parse_scores(study, problems: Problems) -> list[ScoreSpec]:
    """Every declared score of `study` (its own in study.toml, then each included instrument's), problems added."""
    instruments = _instruments(study)
    specs: list[ScoreSpec] = []
    seen: dict[str, str] = {}
    # the included instruments first: a clash of names is then reported in the study's own study.toml
    sources = [(paths(n)[1], n) for n in includes(study.settings) if paths(n)[1] in study.files] + [(STUDY_FILE, None)]
    included = dict(_included_names(study))
    for rel, lib_name in sources:
        text = study.files[rel]
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            problems.add(rel, None, "", f"not valid TOML: {exc}")
            continue
        tables = data.get("scores", [])
        if not isinstance(tables, list):
            problems.add(rel, line_of(text, "scores"), "scores", "must be [[scores]] tables")
            continue
        fixed = included.get(lib_name) if lib_name else None
        for k, raw in enumerate(tables):
            spec = _parse_table(raw, k, rel, text, seen, problems, fixed, instruments)
            if spec is not None:
                specs.append(spec)
    return specs


def _included_names(study) -> list[tuple[str, str]]:
    """(library name, stored instrument name) of each included instrument present in the study's files."""
    keys = {paths(n)[0]: n for n in includes(study.settings)}
    return [(keys[rel], stored) for stored, rel in included_instruments(study.settings, study.files)]


def study_scores(study, instrument: str | None = None) -> list[ScoreSpec]:
    """The declared scores of `study` (of one instrument when named: stored name, or without _vN); a problem ->
    StudyError (a stored study was checked when stored, so only a folder read directly can have one)."""
    problems = Problems()
    specs = parse_scores(study, problems)
    if problems:
        raise StudyError(list(problems))
    if instrument is not None:
        specs = [s for s in specs if instrument in (s.instrument, _stem(s.instrument))]
    return specs


@register_file_check
def check_scores(study, problems: Problems) -> None:
    """`study check`: every ``[instrument] include`` names a shipped instrument once, every score declaration
    (study.toml and the included instruments' TOML files) is well formed and names items that exist."""
    inst = study.settings.get("instrument", {})
    raw = inst.get("include") if isinstance(inst, dict) else None
    text = study.files.get(STUDY_FILE, "")
    if raw is not None:
        line = line_of(text, "include", "instrument")
        names = [raw] if isinstance(raw, str) else raw
        known = shipped()
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            problems.add(STUDY_FILE, line, "instrument.include", "must be a list of shipped instrument names")
        else:
            for n in names:
                if n not in known:
                    problems.add(STUDY_FILE, line, "instrument.include",
                                 f"{n!r} is not a shipped instrument ({', '.join(known)})")
            for n in sorted({n for n in names if names.count(n) > 1}):
                problems.add(STUDY_FILE, line, "instrument.include", f"{n!r} included twice")
        stored = [name for name, _ in study.instrument_files]
        for n in sorted({n for n in stored if stored.count(n) > 1}):
            problems.add(STUDY_FILE, line, "instrument.include", f"two instruments named {n}")
    parse_scores(study, problems)


def score_resolution(spec: ScoreSpec, instrument: Instrument) -> float | None:
    """The step in which a score moves (the resolution at which its values tie, analysis/ranks.py): the greatest
    common divisor of weight x item step over the items, times |multiply|, over the sum of the weights for a mean
    (TLX raw: 5 / 6; a mean of six 1-7 items: 1 / 6; SUS: 2.5). None when it has no fixed step (weights taken from
    the answers, or weights and steps that are not whole numbers)."""
    if spec.weights_from is not None:
        return None
    weights = spec.weights if spec.weights is not None else (1.0,) * len(spec.items)
    terms = [w * instrument.step(item) for w, item in zip(weights, spec.items)]
    if not all(float(t).is_integer() and t != 0 for t in terms):
        return None
    step = 0
    for t in terms:
        step = math.gcd(step, abs(int(t)))
    res = step * abs(spec.multiply) / (abs(sum(weights)) if spec.aggregate == "mean" else 1)
    return res if res > 0 else None
