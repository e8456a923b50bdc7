"""The survey instrument as data: a codebook CSV in a study folder (one row per item, in the spirit of a REDCap
data dictionary; docs/study_folder.md).

Columns: item_id, construct, section, text, response_type, scale_min, scale_max (inclusive range of a scaled, number
or choice item), anchor_low, anchor_high (labels of the two scale ends), choices, reverse_scored (0/1), required (0/1:
the web form refuses to submit without it; an import needs the column). Optional: attribute (the participant
attribute the answer fills), reconstructed, source, and any other column (kept, not interpreted).

response_type is ``likert``/``likertK`` or ``semantic``/``semanticK`` (a K-point scale, 2 <= K <= 11, K =
scale_max - scale_min + 1), ``slider`` (a visual analogue scale: a whole number in scale_min..scale_max on the grid
scale_min + k * step, the optional ``step`` column, default 1; e.g. NASA-TLX 0..100 in steps of 5), ``number``,
``choice`` or ``text``. ``choices`` lists ``code=label`` or REDCap's ``code, label`` pairs separated by ``|``; a
Likert item may label every point this way.

Scaled items (Likert, semantic differential, slider) are the numeric answers the analysis scores and reverses;
:meth:`Instrument.parse` is the one validation of an answer that the web form, the CSV import and the double entry
share.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from functools import cached_property

import pandas as pd

from study.common.problems import Problems, StudyError

SCALED_KINDS = ("likert", "semantic", "slider")
SLIDER = "slider"
DEMOGRAPHIC_TYPES = ("number", "choice")
RESPONSE_TYPE = re.compile(r"^(likert|semantic)(\d+)?$|^(number|choice|text|slider)$")
MIN_POINTS, MAX_POINTS = 2, 11
REQUIRED_COLUMNS = ("item_id", "construct", "section", "text", "response_type", "scale_min", "scale_max",
                    "anchor_low", "anchor_high", "choices", "reverse_scored", "required")
MAX_TEXT = 5000  # characters kept for one free-text answer
MAX_SLIDER_STEPS = 1000  # grid points of a slider beyond which a tablet's finger cannot pick one value


@dataclass(frozen=True)
class Answer:
    """One parsed answer: `value` for integer items, `text` for free text; both None = missing."""

    value: int | None = None
    text: str | None = None

    @property
    def missing(self) -> bool:
        return self.value is None and self.text is None


@dataclass(frozen=True)
class Instrument:
    """A loaded codebook. `items` is the codebook DataFrame indexed by item_id, in questionnaire order."""

    name: str
    items: pd.DataFrame

    @classmethod
    def from_csv(cls, name: str, text: str, rel: str = "codebook.csv", problems=None) -> "Instrument":
        """The instrument of a codebook's CSV text (see :func:`_from_csv`)."""
        return _from_csv(cls, name, text, rel, problems)

    @property
    def version(self) -> str:
        return self.name.rsplit("_v", 1)[-1]

    @property
    def scaled_items(self) -> list[str]:
        """Items answered on a numeric scale (Likert, semantic differentials, sliders), in order."""
        return self.items.index[self.items["response_type"].map(is_scaled)].tolist()

    @property
    def text_items(self) -> list[str]:
        return self.items.index[self.items["response_type"] == "text"].tolist()

    @property
    def reverse_items(self) -> list[str]:
        return self.items.index[self.items["reverse_scored"] == 1].tolist()

    @property
    def constructs(self) -> dict[str, list[str]]:
        """Construct -> its scaled items, in questionnaire order (e.g. {'PU': ['PU1', ...], ...})."""
        scaled = self.items.loc[self.scaled_items]
        return {c: g.index.tolist() for c, g in scaled.groupby("construct", sort=False)}

    @property
    def demographic_items(self) -> list[str]:
        """The socio-demographic / eco-familiarity block (number and choice items), in order."""
        return self.items.index[self.items["response_type"].isin(DEMOGRAPHIC_TYPES)].tolist()

    @property
    def required_items(self) -> list[str]:
        return self.items.index[self.items["required"] == 1].tolist()

    @property
    def sections(self) -> list[tuple[str, list[str]]]:
        """(section title, item ids) in questionnaire order."""
        out: list[tuple[str, list[str]]] = []
        for item, section in self.items["section"].items():
            if not out or out[-1][0] != section:
                out.append((section, []))
            out[-1][1].append(item)
        return out

    def choices(self, item_id: str) -> dict[int, str]:
        """Code -> label of a choice item (empty for other items)."""
        return parse_choices(str(self.items.loc[item_id, "choices"] or ""))

    def parse(self, item_id: str, raw) -> Answer:
        """Validate one raw answer (str, int or None) for `item_id`; '' / None = missing.

        Integer items take an integer within [scale_min, scale_max] (a choice item also takes its label,
        case-insensitive); anything else raises ValueError with a one-line reason.
        """
        meta = self._meta.get(item_id)
        if meta is None:
            raise ValueError(f"unknown item {item_id!r} (not in instrument {self.name})")
        kind, lo, hi, labels, step = meta
        if raw is None or (isinstance(raw, float) and raw != raw):
            return Answer()
        if kind == "text":
            text = str(raw).strip()
            if len(text) > MAX_TEXT:
                raise ValueError(f"{item_id}: answer longer than {MAX_TEXT} characters")
            return Answer(text=text or None)
        if isinstance(raw, bool):
            raise ValueError(f"{item_id}: {raw!r} is not an integer")
        if isinstance(raw, int):
            value = raw
        else:
            s = str(raw).strip()
            if not s:
                return Answer()
            if s.casefold() in labels:
                value = labels[s.casefold()]
            else:
                # "4.0"/"4.00" (how spreadsheets and SPSS write whole numbers) is the integer 4; "4.5" is refused
                whole = re.fullmatch(r"([+-]?\d+)(?:\.0+)?", s)
                if not whole:
                    raise ValueError(f"{item_id}: {s!r} is not an integer")
                value = int(whole.group(1))
        if not lo <= value <= hi:
            raise ValueError(f"{item_id}: value {value} outside {lo}-{hi}")
        if (value - lo) % step:
            below = value - (value - lo) % step
            raise ValueError(f"{item_id}: value {value} is not a step of {step} from {lo} "
                             f"(nearest allowed: {below} or {below + step})")
        return Answer(value=value)

    @cached_property
    def _meta(self) -> dict[str, tuple[str, int | None, int | None, dict[str, int], int]]:
        """item -> (response_type, min, max, {casefolded choice label: code}, step) for fast validation."""
        out = {}
        for item, row in self.items.iterrows():
            lo = None if pd.isna(row["scale_min"]) else int(row["scale_min"])
            hi = None if pd.isna(row["scale_max"]) else int(row["scale_max"])
            labels = {label.casefold(): code for code, label in self.choices(item).items()}
            out[item] = (row["response_type"], lo, hi, labels, self.step(item))
        return out

    def scale(self, item_id: str) -> tuple[int, int]:
        row = self.items.loc[item_id]
        return int(row["scale_min"]), int(row["scale_max"])

    def step(self, item_id: str) -> int:
        """Distance between two allowed answers: a slider's `step` (default 1), 1 for every other item."""
        if "step" not in self.items.columns:
            return 1
        raw = str(self.items.loc[item_id, "step"] or "").strip()
        return int(raw) if raw else 1

    def reverse(self, answers: pd.DataFrame) -> pd.DataFrame:
        """Copy of wide `answers` (columns = item ids) with reverse-scored items mapped x -> min + max - x."""
        out = answers.copy()
        for item in self.reverse_items:
            if item in out:
                lo, hi = self.scale(item)
                out[item] = lo + hi - out[item]
        return out


def is_scaled(response_type: str) -> bool:
    """Likert items, semantic differentials (any number of points) and sliders: answers on a numeric scale."""
    return str(response_type).startswith(SCALED_KINDS)


def parse_choices(raw: str) -> dict[int, str]:
    """``1=Female|2=Male`` or REDCap's ``1, Female | 2, Male`` -> {1: 'Female', 2: 'Male'}; ValueError if malformed."""
    out: dict[int, str] = {}
    for part in filter(None, (p.strip() for p in str(raw).split("|"))):
        m = re.fullmatch(r"([+-]?\d+)\s*[=,]\s*(.*)", part, flags=re.S)
        if not m:
            raise ValueError(f"choice {part!r} is not 'code=label' or 'code, label'")
        code = int(m.group(1))
        if code in out:
            raise ValueError(f"choice code {code} appears twice")
        out[code] = m.group(2).strip()
    return out


def _from_csv(cls, name: str, text: str, rel: str = "codebook.csv", problems=None) -> "Instrument":
    """Parse and check a codebook's text; with `problems` (a list with .add) every problem is added there, else the
    first raises StudyError. Lines are 1-based lines of the CSV (header = line 1)."""
    own = problems is None
    problems = Problems() if own else problems
    n0 = len(problems)
    try:
        items = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
    except Exception as exc:  # noqa: BLE001 - any CSV parser error is a problem of the file
        problems.add(rel, None, "", f"not a readable CSV: {' '.join(str(exc).split())}")
        if own:
            raise StudyError(list(problems)) from None
        return None
    missing = [c for c in REQUIRED_COLUMNS if c not in items.columns]
    if missing:
        problems.add(rel, 1, "", f"missing column(s) {', '.join(missing)}")
    else:
        items.columns = [c.strip() for c in items.columns]
        seen: set[str] = set()
        for k, row in enumerate(items.to_dict("records")):
            _check_row(row, k + 2, rel, seen, problems)
    if len(problems) > n0:
        if own:
            raise StudyError(list(problems)[n0:])
        return None
    items = items.set_index("item_id")
    for col in ("scale_min", "scale_max"):
        items[col] = pd.to_numeric(items[col].replace("", None)).astype("Int64")
    for col in ("reverse_scored", "required"):
        items[col] = items[col].astype(int)
    if "reconstructed" in items:
        items["reconstructed"] = items["reconstructed"].replace("", "0").astype(int)
    return cls(name=name, items=items)


def _check_row(row: dict, line: int, rel: str, seen: set, problems) -> None:
    item = str(row["item_id"]).strip()
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", item):
        problems.add(rel, line, "item_id", f"{item!r}: use letters, digits and _, starting with a letter")
    elif item in seen:
        problems.add(rel, line, "item_id", f"{item!r} appears twice")
    seen.add(item)
    where = item or "item_id"
    kind = str(row["response_type"]).strip()
    m = RESPONSE_TYPE.match(kind)
    if not m:
        problems.add(rel, line, f"{where}.response_type", f"{kind!r} is not likert[K] | semantic[K] | slider | "
                                                          f"number | choice | text")
        return
    if not str(row["text"]).strip():
        problems.add(rel, line, f"{where}.text", "empty question text")
    if not str(row["construct"]).strip():
        problems.add(rel, line, f"{where}.construct", "empty construct (use e.g. DEMO or FEEDBACK for other items)")
    for col in ("reverse_scored", "required"):
        if str(row[col]).strip() not in ("0", "1"):
            problems.add(rel, line, f"{where}.{col}", f"{row[col]!r} is not 0 or 1")
    lo, hi = str(row["scale_min"]).strip(), str(row["scale_max"]).strip()
    step = str(row.get("step", "") or "").strip()
    if step and kind != SLIDER:
        problems.add(rel, line, f"{where}.step", f"only a slider has a step (this item is {kind})")
    if kind == "text":
        if lo or hi:
            problems.add(rel, line, f"{where}.scale_min", "a text item has no scale")
        return
    if not re.fullmatch(r"[+-]?\d+", lo) or not re.fullmatch(r"[+-]?\d+", hi):
        problems.add(rel, line, f"{where}.scale_min", f"a {kind} item needs whole-number scale_min and scale_max")
        return
    lo_i, hi_i = int(lo), int(hi)
    if hi_i <= lo_i:
        problems.add(rel, line, f"{where}.scale_max", f"scale_max {hi_i} must exceed scale_min {lo_i}")
        return
    try:
        choices = parse_choices(row["choices"])
    except ValueError as exc:
        problems.add(rel, line, f"{where}.choices", str(exc))
        return
    if m.group(1):  # Likert / semantic differential
        points = hi_i - lo_i + 1
        if not MIN_POINTS <= points <= MAX_POINTS:
            problems.add(rel, line, f"{where}.scale_max", f"{points} points; a scale has {MIN_POINTS} to "
                                                          f"{MAX_POINTS}")
        if m.group(2) and int(m.group(2)) != points:
            problems.add(rel, line, f"{where}.response_type", f"{kind} but scale_min..scale_max has {points} points")
        if choices and sorted(choices) != list(range(lo_i, hi_i + 1)):
            problems.add(rel, line, f"{where}.choices", f"labels must cover every point {lo_i}..{hi_i} or none")
        if m.group(1) == "semantic" and not (str(row["anchor_low"]).strip() and str(row["anchor_high"]).strip()):
            problems.add(rel, line, f"{where}.anchor_low", "a semantic differential needs both anchors")
    elif kind == "choice":
        if not choices:
            problems.add(rel, line, f"{where}.choices", "a choice item needs choices")
        elif min(choices) < lo_i or max(choices) > hi_i:
            problems.add(rel, line, f"{where}.choices", f"codes must lie within {lo_i}..{hi_i}")
    elif kind == SLIDER:
        _check_slider(where, lo_i, hi_i, step, choices, line, rel, problems)
    if str(row["reverse_scored"]).strip() == "1" and not (m.group(1) or kind == SLIDER):
        problems.add(rel, line, f"{where}.reverse_scored", "only a scaled item can be reverse-scored")


def _check_slider(where: str, lo: int, hi: int, step: str, choices: dict, line: int, rel: str, problems) -> None:
    """A slider: a whole-number step > 0 that divides scale_max - scale_min (so both ends are answers), at most
    MAX_SLIDER_STEPS grid points, no choices (its two anchors label the ends)."""
    if choices:
        problems.add(rel, line, f"{where}.choices", "a slider has no choices (anchor_low and anchor_high label its ends)")
    if not step:
        n = hi - lo
    elif not re.fullmatch(r"\d+", step) or int(step) == 0:
        problems.add(rel, line, f"{where}.step", f"{step!r} is not a whole number above 0")
        return
    elif (hi - lo) % int(step):
        problems.add(rel, line, f"{where}.step", f"step {step} does not divide scale_max - scale_min = {hi - lo} "
                                                 f"(the ends {lo} and {hi} must be answers)")
        return
    else:
        n = (hi - lo) // int(step)
    if n > MAX_SLIDER_STEPS:
        problems.add(rel, line, f"{where}.step", f"{n} steps; a slider has at most {MAX_SLIDER_STEPS}")

