"""The survey instrument as data: a versioned codebook (one row per item, in the spirit of a REDCap data
dictionary) shipped in `study/instruments/<name>_v<N>.csv`.

Columns: item_id, construct, section, text, response_type (likert5 | semantic5 | text), scale_min, scale_max,
anchor_low, anchor_high, reverse_scored (0/1), required (0/1), reconstructed (0/1: wording not printed in the
paper), source (where the wording comes from).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import pandas as pd

INSTRUMENT_DIR = Path(__file__).with_name("instruments")
DEFAULT_INSTRUMENT = "pedas_acceptance_v1"
SCALED_TYPES = ("likert5", "semantic5")


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
    items = pd.read_csv(path, dtype={"item_id": str}, keep_default_na=False).set_index("item_id")
    for col in ("reverse_scored", "required", "reconstructed"):
        items[col] = items[col].astype(int)
    return Instrument(name=name, items=items)
