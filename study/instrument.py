"""The survey instrument as data: a versioned codebook (one row per item, in the spirit of a REDCap data
dictionary) shipped in `study/instruments/<name>_v<N>.csv`.

Columns: item_id, construct, section, text, response_type (likert5 | semantic5 | text | number | choice),
scale_min, scale_max (inclusive range of a scaled, number or choice item), anchor_low, anchor_high (labels of the
two scale ends), choices (``code=label|code=label`` for choice items), reverse_scored (0/1), required (0/1: the web
form refuses to submit without it; an import needs the column), reconstructed (0/1: wording not printed in the
paper), source (where the wording comes from).

The socio-demographic block (construct ``DEMO``: AGE, GENDER, LICENSE_YEARS, STYLE, ECO_FAM) is answered with
integers like every other non-text item: numbers as given, choices as their codes.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import pandas as pd

INSTRUMENT_DIR = Path(__file__).with_name("instruments")
DEFAULT_INSTRUMENT = "pedas_acceptance_v1"
SCALED_TYPES = ("likert5", "semantic5")
DEMOGRAPHIC_TYPES = ("number", "choice")
MAX_TEXT = 5000  # characters kept for one free-text answer


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

    @property
    def version(self) -> str:
        return self.name.rsplit("_v", 1)[-1]

    @property
    def scaled_items(self) -> list[str]:
        """Items answered on a numeric scale (Likert and semantic differentials), in order."""
        return self.items.index[self.items["response_type"].isin(SCALED_TYPES)].tolist()

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
        raw = str(self.items.loc[item_id, "choices"] or "")
        out: dict[int, str] = {}
        for part in filter(None, raw.split("|")):
            code, _, label = part.partition("=")
            out[int(code)] = label.strip()
        return out

    def parse(self, item_id: str, raw) -> Answer:
        """Validate one raw answer (str, int or None) for `item_id`; '' / None = missing.

        Integer items take an integer within [scale_min, scale_max] (a choice item also takes its label,
        case-insensitive); anything else raises ValueError with a one-line reason.
        """
        meta = self._meta.get(item_id)
        if meta is None:
            raise ValueError(f"unknown item {item_id!r} (not in instrument {self.name})")
        kind, lo, hi, labels = meta
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
        return Answer(value=value)

    @cached_property
    def _meta(self) -> dict[str, tuple[str, int | None, int | None, dict[str, int]]]:
        """item -> (response_type, min, max, {casefolded choice label: code}) for fast validation."""
        out = {}
        for item, row in self.items.iterrows():
            lo = None if pd.isna(row["scale_min"]) else int(row["scale_min"])
            hi = None if pd.isna(row["scale_max"]) else int(row["scale_max"])
            labels = {label.casefold(): code for code, label in self.choices(item).items()}
            out[item] = (row["response_type"], lo, hi, labels)
        return out

    def scale(self, item_id: str) -> tuple[int, int]:
        row = self.items.loc[item_id]
        return int(row["scale_min"]), int(row["scale_max"])

    def reverse(self, answers: pd.DataFrame) -> pd.DataFrame:
        """Copy of wide `answers` (columns = item ids) with reverse-scored items mapped x -> min + max - x."""
        out = answers.copy()
        for item in self.reverse_items:
            if item in out:
                lo, hi = self.scale(item)
                out[item] = lo + hi - out[item]
        return out


@lru_cache(maxsize=None)
def load_instrument(name: str = DEFAULT_INSTRUMENT) -> Instrument:
    """Load a codebook by name (file stem), e.g. ``load_instrument().constructs['PEoU']``."""
    path = INSTRUMENT_DIR / f"{name}.csv"
    if not path.exists():
        known = ", ".join(sorted(p.stem for p in INSTRUMENT_DIR.glob("*.csv")))
        raise ValueError(f"unknown instrument {name!r} (known: {known})")
    items = pd.read_csv(path, dtype=str, keep_default_na=False).set_index("item_id")
    for col in ("scale_min", "scale_max"):
        items[col] = pd.to_numeric(items[col].replace("", None)).astype("Int64")
    for col in ("reverse_scored", "required", "reconstructed"):
        items[col] = items[col].astype(int)
    return Instrument(name=name, items=items)
