"""A study as data: a folder of plain files, checked on load (docs/study_folder.md).

    studies/<name>/
        study.toml      title, participant texts, id pattern, participant attributes, conditions, the files below
        codebook.csv    the survey instrument (one row per item, in the spirit of a REDCap data dictionary)
        protocol.json   phases, orders (counterbalancing), planned durations; several protocols may be listed
        model.lav       measurement model, hierarchical regression steps and hypotheses in lavaan syntax
        ...             optional files the study declares (published values, log mapping, route, KPIs)

:func:`read_folder` reads the declared files as text; :func:`parse` turns those texts into a
:class:`StudyDefinition` and collects *every* problem (file, line, field, message) instead of stopping at the first;
:func:`load` raises a :class:`StudyError` naming the first problem and how many there are. The store keeps the texts
(table ``study_definitions``), so a stored study is re-parsed from exactly what was checked in, never from the folder;
:func:`from_stored` reads it back without checking it again, its declared files parsed when first used.
"""
from __future__ import annotations

import hashlib
import io
import re
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from study.common.errors import UserError, check_name
from study.common.file_checks import run_file_checks
from study.common.problems import Problem, Problems, StudyError
from study.common.toml_lines import line_of
from study.folder.instrument_library import (
    included_files,
    included_instruments,
    is_library_key,
)
from study.folder.protocol_file import parse_protocol

STUDY_FILE = "study.toml"
ATTRIBUTE_TYPES = ("integer", "number", "choice", "text")
NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")   # attribute, condition, construct and item names
MAX_ID_LENGTH = 64
#: names an attribute cannot take: columns that participant listings, exports and KPI tables already have
RESERVED_ATTRIBUTES = ("participant_id", "protocol", "order", "study_version", "phase", "phase_outcome",
                       "excluded", "created_at", "condition")
#: files a study may declare in [files]; the value names the key's meaning in the docs
FILE_KEYS = {"instrument": "survey codebook (CSV)", "protocols": "protocol files (JSON), the first is the default",
             "model": "analysis model (lavaan syntax)", "published": "published values to compare with (CSV)",
             "log_mapping": "drive-log column mapping (TOML)", "route": "route: sections, lights, stop signs",
             "kpis": "declared KPIs (TOML)"}



# ---------------------------------------------------------------------------------------------- declarations
@dataclass(frozen=True)
class Attribute:
    """A participant attribute (e.g. age): type integer | number | choice | text, range or choices, label."""

    name: str
    type: str
    label: str = ""
    min: float | None = None
    max: float | None = None
    choices: tuple[str, ...] = ()
    required: bool = False

    @property
    def categorical(self) -> bool:
        return self.type in ("choice", "text")

    def parse(self, raw: Any) -> Any:
        """The typed value of `raw` (None/'' = missing); out of range or unknown choice -> UserError."""
        if raw is None or (isinstance(raw, float) and raw != raw) or (isinstance(raw, str) and not raw.strip()):
            if self.required:
                raise UserError(f"{self.name} is required")
            return None
        if self.type == "text":
            return str(raw).strip()
        if self.type == "choice":
            value = str(raw).strip()
            if value not in self.choices:
                raise UserError(f"{self.name} must be one of {'|'.join(self.choices)}, not {value!r}")
            return value
        if isinstance(raw, bool):
            raise UserError(f"{self.name} must be a number, not {raw!r}")
        try:
            num = float(raw)
        except (TypeError, ValueError):
            raise UserError(f"{self.name} must be a {'whole ' if self.type == 'integer' else ''}number, "
                            f"not {raw!r}") from None
        if num != num or num in (float("inf"), float("-inf")):
            raise UserError(f"{self.name} must be a finite number, not {raw!r}")
        if self.type == "integer":
            if num != int(num):
                raise UserError(f"{self.name} must be a whole number, not {raw!r}")
            num = int(num)
        if (self.min is not None and num < self.min) or (self.max is not None and num > self.max):
            raise UserError(f"{self.name} must be between {_num(self.min)} and {_num(self.max)}, not {_num(num)}")
        return num


@dataclass(frozen=True)
class Condition:
    name: str
    label: str = ""


@dataclass(frozen=True)
class Check:
    """A rule over participant attributes as a DuckDB SQL expression; refused registrations print `message`."""

    sql: str
    message: str


@dataclass(frozen=True)
class RegressionModel:
    """One hierarchical regression: ``steps[k]`` are all predictors of step k+1 (nested, cumulative)."""

    name: str
    dv: str
    steps: tuple[tuple[str, ...], ...]

    @property
    def label(self) -> str:
        return f"{' + '.join(self.steps[-1])} -> {self.dv}"

    @property
    def blocks(self) -> list[list[str]]:
        """Predictors entered at each step (what a block-wise regression enters)."""
        out, seen = [], []
        for step in self.steps:
            out.append([p for p in step if p not in seen])
            seen.extend(out[-1])
        return out


@dataclass(frozen=True)
class Hypothesis:
    """A labelled regression path: read in `model` at `step`; sign '>' / '<' (one expected direction) or '!='."""

    hypothesis: str
    predictor: str
    dv: str
    model: str
    step: int
    sign: str = "!="

    @property
    def path(self) -> str:
        return f"{self.predictor} -> {self.dv}"


@dataclass(frozen=True)
class AnalysisModel:
    """The parsed model file: final measurement model, regressions and hypotheses."""

    measurement: dict[str, tuple[str, ...]]
    regressions: tuple[RegressionModel, ...]
    hypotheses: tuple[Hypothesis, ...]


@dataclass(frozen=True)
class StudyDefinition:
    """A checked study. `files` maps each declared file (relative path) to its text; `hash` covers all of them."""

    study_id: str
    title: str
    description: str
    id_pattern: str
    id_example: str
    attributes: tuple[Attribute, ...]
    conditions: tuple[Condition, ...]
    checks: tuple[Check, ...]
    settings: dict[str, Any]
    files: dict[str, str] = field(repr=False)
    paths: dict[str, Any] = field(repr=False)
    summary: str = ""   # researcher-facing: what the study compares and how (the report's description)

    # ---------------------------------------------------------------- identity
    @cached_property
    def hash(self) -> str:
        return definition_hash(self.files)

    @property
    def condition_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.conditions)

    def attribute(self, name: str) -> Attribute:
        for a in self.attributes:
            if a.name == name:
                return a
        raise UserError(f"unknown participant attribute {name!r} (study {self.study_id}: "
                        f"{', '.join(a.name for a in self.attributes) or 'none declared'})")

    def validate_id(self, participant_id: str) -> str:
        # the schema refuses empty ids, whitespace and more than 64 characters whatever the study's pattern says
        if (not isinstance(participant_id, str) or not 0 < len(participant_id) <= MAX_ID_LENGTH
                or re.search(r"\s", participant_id) or not re.fullmatch(self.id_pattern, participant_id)):
            raise UserError(f"bad participant id {participant_id!r}: study {self.study_id} uses ids matching "
                            f"{self.id_pattern}, e.g. {self.id_example}")
        return participant_id

    def check_condition(self, condition: str) -> str:
        if condition not in self.condition_names:
            raise UserError(f"unknown condition {condition!r} (study {self.study_id}: "
                            f"{'|'.join(self.condition_names)})")
        return condition

    # ---------------------------------------------------------------- declared files
    def text(self, key: str) -> str | None:
        """Text of the (first) file declared under [files] `key`, None when not declared."""
        rel = self.paths.get(key)
        if isinstance(rel, list):
            rel = rel[0] if rel else None
        return None if rel is None else self.files[rel]

    @cached_property
    def instruments(self) -> dict[str, Any]:
        """Instrument name -> :class:`study.folder.instrument.Instrument` (the study's current versions), the default
        (first declared) first."""
        from study.folder.instrument import (
            Instrument,  # pandas: loaded by the commands that use a codebook
        )

        return {name: Instrument.from_csv(name, self.files[rel], rel) for name, rel in self.instrument_files}

    @property
    def instrument_files(self) -> list[tuple[str, str]]:
        """(stored instrument name, codebook path) of each declared codebook, in declaration order. One codebook
        (``[files] instrument = "codebook.csv"``) is named ``<[instrument] name>_v<version>``; several (a list: a
        pre-study, a post-drive and a final questionnaire) are each named after their file,
        ``<file stem>_v<version>``, the version ``[instrument.versions] <stem>`` or else ``[instrument] version``."""
        rel = self.paths.get("instrument")
        included = included_instruments(self.settings, self.files)   # shipped ones, [instrument] include
        if not rel:
            return included
        if not isinstance(rel, list):
            return [(self.instrument_name, rel)] + included
        inst = self.settings.get("instrument", {})
        versions = inst.get("versions", {}) if isinstance(inst.get("versions", {}), dict) else {}
        return [(f"{Path(r).stem}_v{versions.get(Path(r).stem, inst.get('version', 1))}", r) for r in rel] + included

    @property
    def instrument_name(self) -> str:
        """The default instrument's stored name."""
        if isinstance(self.paths.get("instrument"), list) or (not self.paths.get("instrument")
                                                              and self.instrument_files):
            return self.instrument_files[0][0]
        inst = self.settings.get("instrument", {})
        return f"{inst.get('name', self.study_id)}_v{inst.get('version', 1)}"

    def instrument(self, name: str | None = None):
        """The study's instrument (`name` None = its only one); unknown name -> UserError."""
        if not self.instruments:
            raise UserError(f"study {self.study_id} declares no survey instrument")
        check_name("instrument", name, self.instruments)
        name = name or next(iter(self.instruments))
        if name not in self.instruments:
            raise UserError(f"unknown instrument {name!r} (study {self.study_id}: {', '.join(self.instruments)})")
        return self.instruments[name]

    @cached_property
    def protocols(self) -> dict[str, Any]:
        """Protocol name -> :class:`study.folder.protocol_file.Protocol`, the default (first declared) first."""
        out = {}
        for rel in self.paths.get("protocols", []):
            proto = parse_protocol(self.files[rel], rel)
            out[proto.name] = proto
        return out

    def protocol(self, name: str | None = None):
        if not self.protocols:
            raise UserError(f"study {self.study_id} declares no protocol")
        check_name("protocol", name, self.protocols)
        name = name or next(iter(self.protocols))
        if name not in self.protocols:
            raise UserError(f"unknown protocol {name!r} (study {self.study_id}: {', '.join(self.protocols)})")
        return self.protocols[name]

    @cached_property
    def model(self) -> AnalysisModel | None:
        """The model file parsed on first use (:func:`parse_model`, with semopy's lavaan parser); None when
        the study declares none. A stored study is only parsed here, by the commands that use its model."""
        text = self.text("model")
        return None if text is None else parse_model(text, self.paths["model"], Problems(), strict=True)

    @property
    def alpha(self) -> float:
        return float(self.settings.get("analysis", {}).get("alpha", 0.05))


# ---------------------------------------------------------------------------------------------- reading
def definition_hash(files: dict[str, str]) -> str:
    h = hashlib.sha256()
    for rel in sorted(files):
        h.update(rel.encode() + b"\0" + files[rel].encode() + b"\0")
    return h.hexdigest()


def read_folder(folder: str | Path) -> dict[str, str]:
    """{relative path: text} of study.toml and every file it declares (undeclared files are not read).

    A missing folder or study.toml raises StudyError; a declared file that is missing is left out here and
    reported by :func:`parse`.
    """
    folder = Path(folder)
    if not (folder / STUDY_FILE).is_file():
        raise StudyError([Problem(str(folder), None, "", f"not a study folder (no {STUDY_FILE}; "
                                                         f"`pedas-study study new DIR` writes a template)")])
    files = {STUDY_FILE: (folder / STUDY_FILE).read_text(encoding="utf-8")}
    try:
        data = tomllib.loads(files[STUDY_FILE])
    except tomllib.TOMLDecodeError:
        return files  # parse() reports it with its line
    for rel in _declared(data.get("files", {})):
        path = folder / rel
        if path.is_file() and folder.resolve() in path.resolve().parents:
            files[rel] = path.read_text(encoding="utf-8")
    files.update(included_files(data))   # shipped instruments the study includes, kept with its own files
    return files


def _declared(files_section: Any) -> list[str]:
    if not isinstance(files_section, dict):
        return []
    out: list[str] = []
    for v in files_section.values():
        out.extend(v if isinstance(v, list) else [v])
    return [str(v) for v in out if isinstance(v, str)]


def load(folder: str | Path, units: bool = True) -> StudyDefinition:
    """Read and check a study folder; any problem -> StudyError (first problem, and how many). Without `units`, the
    checks that read units (log mapping, route: pint's unit registry, about half a second) are left out: for a
    command that uses neither (``analyze``, ``plan power``); ``study check`` and ``init`` check everything."""
    return from_files(read_folder(folder), units=units)


def check(folder: str | Path) -> list[Problem]:
    """Every problem of a study folder (empty = the study loads)."""
    try:
        files = read_folder(folder)
    except StudyError as exc:
        return exc.problems
    problems = Problems()
    _parse(files, problems)
    return list(problems)


def from_files(files: dict[str, str], units: bool = True) -> StudyDefinition:
    """Parse stored or read texts and check every declared file (without `units`: not the checks that read units,
    :func:`load`); any problem -> StudyError."""
    problems = Problems()
    study = _parse(files, problems, units=units)
    if problems:
        raise StudyError(list(problems))
    return study


def from_stored(files: dict[str, str]) -> StudyDefinition:
    """A study as the store holds it: texts that :func:`from_files` checked when they were stored (the stored hash
    names exactly those texts), so they are not checked again. Only study.toml is parsed here; each declared file
    (codebook, protocols, model) is parsed by the property that returns it, on first use, by the same parser as
    the check. Reading a stored study thus loads no model or KPI parser unless a command uses them. A problem of
    study.toml -> StudyError."""
    problems = Problems()
    study = _parse(files, problems, check_files=False)
    if problems:
        raise StudyError(list(problems))
    return study


# ---------------------------------------------------------------------------------------------- parsing
def _toml_field(text: str, line: int) -> str:
    """The dotted name (table.key) a line of a TOML text is about, as far as its header and key tell."""
    lines = text.splitlines()
    key = None
    if 0 < line <= len(lines):
        m = re.match(r"^\s*([A-Za-z0-9_-]+)\s*=", lines[line - 1])
        key = m.group(1) if m else None
    table = None
    for ln in reversed(lines[:line]):
        m = re.match(r"^\s*\[\[?\s*([A-Za-z0-9_.-]+)\s*\]\]?", ln)
        if m:
            table = m.group(1)
            break
    return ".".join(x for x in (table, key) if x) or "toml"


def _parse(files: dict[str, str], problems: Problems, check_files: bool = True,
           units: bool = True) -> StudyDefinition | None:
    """study.toml and, with `check_files`, the checks of its SQL rules and of every declared file (with `units`,
    also those that read units)."""
    text = files.get(STUDY_FILE, "")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        line = int(m.group(1)) if m else max(1, len(text.splitlines()))  # "at end of document": the last line
        problems.add(STUDY_FILE, line, _toml_field(text, line), f"not valid TOML: {exc}")
        return None

    def need(section: dict, key: str, sect: str, kind: type, default: Any = ...) -> Any:
        if key not in section:
            if default is ...:
                problems.add(STUDY_FILE, line_of(text, "", sect) if sect else None, f"{sect}.{key}".strip("."),
                             "missing")
            return None if default is ... else default
        value = section[key]
        if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
            problems.add(STUDY_FILE, line_of(text, key, sect or None), f"{sect}.{key}".strip("."),
                         "must be " + (kind.__name__ if not isinstance(kind, tuple)
                                       else " or ".join(k.__name__ for k in kind)))
            return None if default is ... else default
        return value

    s = data.get("study", {})
    if not isinstance(s, dict) or "study" not in data:
        problems.add(STUDY_FILE, None, "study", "missing the [study] table")
        s = {}
    study_id = need(s, "id", "study", str) or "?"
    if study_id != "?" and not re.fullmatch(r"[a-z][a-z0-9_-]{0,39}", study_id):
        problems.add(STUDY_FILE, line_of(text, "id", "study"), "study.id",
                     f"{study_id!r}: use lower-case letters, digits, _ or - (at most 40, starting with a letter)")
    title = need(s, "title", "study", str) or ""
    description = need(s, "description", "study", str, "")
    summary = need(s, "summary", "study", str, "")

    p = data.get("participants", {})
    id_pattern = need(p, "id_pattern", "participants", str) or r"^$"
    id_example = need(p, "id_example", "participants", str) or ""
    try:
        rx = re.compile(id_pattern)
        if id_example and not rx.fullmatch(id_example):
            problems.add(STUDY_FILE, line_of(text, "id_example", "participants"), "participants.id_example",
                         f"{id_example!r} does not match id_pattern {id_pattern}")
    except re.error as exc:
        problems.add(STUDY_FILE, line_of(text, "id_pattern", "participants"), "participants.id_pattern",
                     f"not a regular expression: {exc}")

    attributes = []
    for k, raw in enumerate(data.get("attributes", [])):
        attr = _attribute(raw, k, text, problems)
        if attr:
            if any(a.name == attr.name for a in attributes):
                problems.add(STUDY_FILE, line_of(text, "name", "attributes", k), f"attributes[{k}].name",
                             f"{attr.name!r} declared twice")
            attributes.append(attr)

    conditions = []
    for k, raw in enumerate(data.get("conditions", [])):
        line = line_of(text, "name", "conditions", k)
        if not isinstance(raw, dict) or not isinstance(raw.get("name"), str) or not NAME.match(raw["name"]):
            problems.add(STUDY_FILE, line, f"conditions[{k}].name", "needs a name of letters, digits and _")
            continue
        if any(c.name == raw["name"] for c in conditions):
            problems.add(STUDY_FILE, line, f"conditions[{k}].name", f"{raw['name']!r} declared twice")
        conditions.append(Condition(raw["name"], str(raw.get("label", raw["name"]))))
    if not conditions:
        problems.add(STUDY_FILE, line_of(text, "", "conditions"), "conditions",
                     "declare at least one [[conditions]] with a name")

    checks = []
    for k, raw in enumerate(data.get("checks", [])):
        if not isinstance(raw, dict) or not isinstance(raw.get("sql"), str) or not isinstance(raw.get("message"), str):
            problems.add(STUDY_FILE, line_of(text, "", "checks", k), f"checks[{k}]", "needs sql and message")
            continue
        checks.append(Check(raw["sql"], raw["message"]))
    if check_files:
        _check_sql(checks, attributes, text, problems)

    paths = data.get("files", {})
    if not isinstance(paths, dict):
        problems.add(STUDY_FILE, line_of(text, "", "files"), "files", "must be a table")
        paths = {}
    clean: dict[str, Any] = {}
    for key, value in paths.items():
        line = line_of(text, key, "files")
        if key not in FILE_KEYS:
            problems.add(STUDY_FILE, line, f"files.{key}", f"unknown key (known: {', '.join(FILE_KEYS)})")
            continue
        values = value if isinstance(value, list) else [value]
        if key == "protocols" and not isinstance(value, list):
            problems.add(STUDY_FILE, line, f"files.{key}", "must be a list of file names")
        if key == "instrument" and isinstance(value, list):
            stems = [Path(v).stem for v in values if isinstance(v, str)]
            bad = [v for v in stems if not NAME.match(v)] or sorted({v for v in stems if stems.count(v) > 1})
            if not values or bad:
                problems.add(STUDY_FILE, line, f"files.{key}", "several codebooks are named after their files: "
                             "distinct names of letters, digits and _ (" + ", ".join(bad or ["none given"]) + ")")
                continue
        if not all(isinstance(v, str) for v in values):
            problems.add(STUDY_FILE, line, f"files.{key}", "must name files relative to the study folder")
            continue
        for v in values:
            if Path(v).is_absolute() or ".." in Path(v).parts:
                problems.add(STUDY_FILE, line, f"files.{key}", f"{v!r}: files must lie inside the study folder")
            elif v not in files:
                problems.add(STUDY_FILE, line, f"files.{key}", f"file {v!r} not found in the study folder")
        clean[key] = list(values) if key == "protocols" or isinstance(value, list) else values[0]
    if "protocols" not in clean:
        problems.add(STUDY_FILE, line_of(text, "", "files"), "files.protocols", "declare at least one protocol")

    settings = {k: v for k, v in data.items() if k not in ("study", "participants", "attributes", "conditions",
                                                             "checks", "files")}
    inst = settings.get("instrument", {})
    if inst and (not isinstance(inst.get("name", ""), str) or not isinstance(inst.get("version", 1), int)):
        problems.add(STUDY_FILE, line_of(text, "", "instrument"), "instrument",
                     "name must be text and version a whole number")
    alpha = settings.get("analysis", {}).get("alpha", 0.05)
    if not isinstance(alpha, (int, float)) or not 0 < alpha < 1:
        problems.add(STUDY_FILE, line_of(text, "alpha", "analysis"), "analysis.alpha", "must be in (0, 1)")

    study = StudyDefinition(study_id=study_id, title=title, description=description, summary=summary,
                            id_pattern=id_pattern,
                            id_example=id_example, attributes=tuple(attributes), conditions=tuple(conditions),
                            checks=tuple(checks), settings=settings,
                            files={k: v for k, v in files.items()
                                   if k == STUDY_FILE or k in _declared(clean) or is_library_key(k)},
                            paths=clean)
    if check_files:
        _check_files(study, problems, units)
    return study


def _attribute(raw: Any, k: int, text: str, problems: Problems) -> Attribute | None:
    line = line_of(text, "name", "attributes", k)
    fld = f"attributes[{k}]"
    if not isinstance(raw, dict) or not isinstance(raw.get("name"), str) or not NAME.match(raw["name"]):
        problems.add(STUDY_FILE, line, f"{fld}.name", "needs a name of letters, digits and _, starting with a letter")
        return None
    if raw["name"] in RESERVED_ATTRIBUTES:
        problems.add(STUDY_FILE, line, f"{fld}.name", f"{raw['name']!r} is reserved "
                                                      f"({', '.join(RESERVED_ATTRIBUTES)})")
        return None
    kind = raw.get("type")
    if kind not in ATTRIBUTE_TYPES:
        problems.add(STUDY_FILE, line_of(text, "type", "attributes", k), f"{fld}.type",
                     f"{kind!r} is not one of {'|'.join(ATTRIBUTE_TYPES)}")
        return None
    lo, hi = raw.get("min"), raw.get("max")
    for key, v in (("min", lo), ("max", hi)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            problems.add(STUDY_FILE, line_of(text, key, "attributes", k), f"{fld}.{key}", "must be a number")
            return None
    if lo is not None and hi is not None and lo > hi:
        problems.add(STUDY_FILE, line_of(text, "min", "attributes", k), f"{fld}.min", f"min {lo} > max {hi}")
    choices = raw.get("choices", [])
    if kind == "choice" and (not isinstance(choices, list) or len(choices) < 2
                             or not all(isinstance(c, str) and c for c in choices)
                             or len(set(choices)) != len(choices)):
        problems.add(STUDY_FILE, line_of(text, "choices", "attributes", k), f"{fld}.choices",
                     "a choice attribute needs a list of at least 2 distinct texts")
        return None
    return Attribute(name=raw["name"], type=kind, label=str(raw.get("label", raw["name"])), min=lo, max=hi,
                     choices=tuple(choices) if kind == "choice" else (), required=bool(raw.get("required", False)))


def _check_sql(checks: list[Check], attributes: list[Attribute], text: str, problems: Problems) -> None:
    """Each check must be a boolean SQL expression over the declared attributes (tried on an empty table)."""
    if not checks:
        return
    import duckdb

    types = {"integer": "BIGINT", "number": "DOUBLE", "choice": "VARCHAR", "text": "VARCHAR"}
    cols = ", ".join(f'"{a.name}" {types[a.type]}' for a in attributes) or "_none INTEGER"
    con = duckdb.connect()
    try:
        con.execute(f"CREATE TABLE p ({cols})")
        for k, c in enumerate(checks):
            try:
                con.execute(f"SELECT CAST(({c.sql}) AS BOOLEAN) FROM p").fetchall()
            except duckdb.Error as exc:
                problems.add(STUDY_FILE, line_of(text, "sql", "checks", k), f"checks[{k}].sql",
                             " ".join(str(exc).split())[:200])
    finally:
        con.close()


def _check_files(study: StudyDefinition, problems: Problems, units: bool = True) -> None:
    """Parse every declared file and cross-check names between them (with `units`, also the checks that read
    units)."""
    import pandas as pd

    from study.folder.instrument import Instrument

    instrument = None   # the default (first) instrument: the model file's items are its items
    first = True
    for name, rel in study.instrument_files:
        if rel not in study.files:
            first = False
            continue
        try:
            ins = Instrument.from_csv(name, study.files[rel], rel, problems=problems)
        except StudyError:
            ins = None
        if ins is not None:
            _check_item_attributes(study, ins, rel, problems)
        if first:
            instrument, first = ins, False
    conditions = set(study.condition_names)
    for rel in study.paths.get("protocols", []):
        if rel not in study.files:
            continue
        try:
            proto = parse_protocol(study.files[rel], rel)
        except UserError as exc:  # "<rel>[:line]: message" -> the line and message of the problem
            m = re.match(rf"{re.escape(rel)}(?::(\d+))?: (.*)$", str(exc), flags=re.S)
            problems.add(rel, int(m.group(1)) if m and m.group(1) else None, "",
                         m.group(2) if m else str(exc))
            continue
        for ph in proto.steps:
            if ph.condition is not None and ph.condition not in conditions:
                problems.add(rel, _json_line(study.files[rel], ph.name), f"phases.{ph.name}.condition",
                             f"{ph.condition!r} is not a declared condition ({'|'.join(study.condition_names)})")
    from study.folder.occasions import check_occasions

    check_occasions(study, problems)
    rel = study.paths.get("model")
    if rel in study.files:
        model = parse_model(study.files[rel], rel, problems)
        if model is not None:
            _check_model_names(study, model, instrument, rel, problems)
    rel = study.paths.get("published")
    if rel in study.files:
        try:
            pd.read_csv(io.StringIO(study.files[rel]))
        except Exception as exc:  # noqa: BLE001 - any parser error is a problem of the file
            problems.add(rel, None, "", f"not a readable CSV: {' '.join(str(exc).split())}")
    # the checks of the modules that own a declared file (log mapping, route, ...)
    run_file_checks(study, problems, units)


def _json_line(text: str, name: str) -> int | None:
    for i, ln in enumerate(text.splitlines(), start=1):
        if re.search(rf'"name"\s*:\s*"{re.escape(name)}"', ln):
            return i
    return None


def _check_item_attributes(study: StudyDefinition, instrument, rel: str, problems: Problems) -> None:
    """An item that fills a participant attribute must name a declared one and fit its type."""
    if "attribute" not in instrument.items.columns:
        return
    for pos, (item, name) in enumerate(instrument.items["attribute"].items(), start=2):
        if not name:
            continue
        attrs = {a.name: a for a in study.attributes}
        if name not in attrs:
            problems.add(rel, pos, f"{item}.attribute", f"{name!r} is not a declared participant attribute")
            continue
        a, kind = attrs[name], instrument.items.loc[item, "response_type"]
        if a.type == "choice":
            codes = sorted(instrument.choices(item))
            if kind != "choice" or codes != list(range(1, len(a.choices) + 1)):
                problems.add(rel, pos, f"{item}.attribute", f"a choice item with codes 1..{len(a.choices)} is "
                                                            f"needed for attribute {name} ({'|'.join(a.choices)})")
        elif a.type in ("integer", "number") and kind not in ("number", "choice") and not kind.startswith(
                ("likert", "semantic")):
            problems.add(rel, pos, f"{item}.attribute", f"a numeric item is needed for attribute {name}")


# ---------------------------------------------------------------------------------------------- model file
def parse_model(text: str, rel: str, problems: Problems, strict: bool = False) -> AnalysisModel | None:
    """Parse a model file in lavaan syntax (semopy's parser reads every line; :mod:`study.folder.lavaan_parser` runs its
    file without importing the rest of semopy).

    * ``C =~ i1 + i2 + ...``  the final measurement model (CFA): construct C measured by items.
    * ``Y ~ x1 + x2``         one step of a hierarchical regression; consecutive ``~`` lines with the same
                              left side are the steps of one model, each listing *all* predictors of that step
                              (nested); a blank line or another dependent variable starts the next model.
    * ``H1*x``                a label on a predictor marks a hypothesis, read in that model at that step.
    * ``H1 > 0`` / ``H1 < 0`` the expected sign (one-sided verdict); a label without one is tested two-sided.
    """
    from study.folder.lavaan_parser import parser

    p = parser()
    separate_token, parse_rvalues = p.separate_token, p.parse_rvalues

    n0 = len(problems)
    measurement: dict[str, tuple[str, ...]] = {}
    models: list[RegressionModel] = []
    labels: dict[str, Hypothesis] = {}
    signs: dict[str, str] = {}
    current: dict[str, Any] | None = None

    def close():
        nonlocal current
        if current:
            models.append(RegressionModel(str(len(models) + 1), current["dv"], tuple(current["steps"])))
        current = None

    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            close()
            continue
        try:
            kind, groups = separate_token(line)
        except SyntaxError:
            problems.add(rel, no, "", f"not lavaan syntax: {line!r}")
            continue
        if kind != 0:
            problems.add(rel, no, "", f"unsupported statement {line!r} (use =~, ~ and label > 0 / < 0)")
            continue
        lhs, op, rhs = (g.strip() for g in groups)
        try:
            rv = parse_rvalues(rhs)
        except Exception:  # noqa: BLE001 - semopy raises a bare Exception for a bad right side
            problems.add(rel, no, "", f"cannot read the right side of {line!r}")
            continue
        if op == "=~":
            close()
            if lhs in measurement:
                problems.add(rel, no, lhs, "construct measured twice")
            if len(rv) < 2:
                problems.add(rel, no, lhs, "a construct needs at least 2 items")
            measurement[lhs] = tuple(rv)
        elif op == "~":
            preds = tuple(rv)
            if current and current["dv"] != lhs:
                close()
            if current:
                prev = current["steps"][-1]
                if not set(prev) <= set(preds):
                    problems.add(rel, no, lhs, f"step {len(current['steps']) + 1} must repeat all predictors of "
                                               f"the step before ({' + '.join(prev)})")
            else:
                current = {"dv": lhs, "steps": []}
            if lhs in preds:
                problems.add(rel, no, lhs, "a variable cannot predict itself")
            current["steps"].append(preds)
            for name, label in rv.items():
                if label is None:
                    continue
                if label in labels:
                    problems.add(rel, no, label, "label used twice (one label = one hypothesis)")
                labels[label] = Hypothesis(label, name, lhs, str(len(models) + 1), len(current["steps"]))
        elif op in (">", "<"):
            if list(rv) != ["0"]:
                problems.add(rel, no, lhs, "a hypothesis sign compares its label with 0, e.g. H1 > 0")
            signs[lhs] = op
        else:
            problems.add(rel, no, "", f"operator {op!r} is not supported here (use =~, ~, > 0, < 0)")
    close()
    for label, op in signs.items():
        if label not in labels:
            problems.add(rel, None, label, "sign given for a label that marks no regression path")
    # hypotheses in the order of their sign lines, then unsigned ones in the order of appearance
    order = [lb for lb in signs if lb in labels] + [lb for lb in labels if lb not in signs]
    hyps = tuple(Hypothesis(labels[lb].hypothesis, labels[lb].predictor, labels[lb].dv, labels[lb].model,
                            labels[lb].step, signs.get(lb, "!=")) for lb in order)
    if len(problems) > n0:
        if strict:
            raise StudyError(list(problems)[n0:])
        return None
    return AnalysisModel(measurement, tuple(models), hyps)


def _check_model_names(study: StudyDefinition, model: AnalysisModel, instrument, rel: str,
                       problems: Problems) -> None:
    lines = study.files[rel].splitlines()

    def line_of(word: str) -> int | None:
        for i, ln in enumerate(lines, start=1):
            if re.search(rf"\b{re.escape(word)}\b", ln.split("#", 1)[0]):
                return i
        return None

    items = set(instrument.scaled_items) if instrument is not None else set()
    # a declared codebook that did not parse has its own problems; its items are not known, so not reported again
    declared = study.instrument_files
    unknown_items = instrument is not None or not declared or declared[0][1] not in study.files
    for construct, its in model.measurement.items():
        for it in its:
            if unknown_items and it not in items:
                problems.add(rel, line_of(it), construct, f"{it!r} is not a scaled item of the instrument")
    attrs = {a.name for a in study.attributes}
    for m in model.regressions:
        for name in (m.dv, *m.steps[-1]):
            if name not in model.measurement and name not in attrs:
                problems.add(rel, line_of(name), m.dv, f"{name!r} is neither a construct of the measurement model "
                                                       f"nor a participant attribute")
        if m.dv in attrs:
            problems.add(rel, line_of(m.dv), m.dv, "the dependent variable must be a construct")


def _num(x: float | None) -> str:
    return "?" if x is None else f"{x:g}"
