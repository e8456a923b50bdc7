"""`participant list` without pandas prints what the DataFrame listing printed: participant_rows + format_rows
against list_participants + format_frame, byte for byte, for every format, on real stores (the paper's study, the
lane-keeping study, a study with a free-text attribute) and on seeded random tables of every value kind."""
from __future__ import annotations

import datetime as dt
import random
import shutil
import struct

import numpy as np
import pandas as pd
import pytest

from pedas_study.cli.common import LIST_FORMATS, format_frame
from pedas_study.cli.rows_text import format_rows
from study.people.exclusions import exclude
from study.people.participants import add_participant, list_participants, participant_rows
from study.people.protocol import advance
from study.store.store import Store
from tests.conftest import LK_STUDY

DAY = dt.datetime(2026, 3, 2, 8, 0)  # in the past: times ahead of the clock are refused


def both(db, fmt: str) -> tuple[str, str]:
    """(format_frame of list_participants, format_rows of participant_rows) of the store at `db`."""
    with Store.open(db, read_only=True) as st:
        df = list_participants(st)
        columns, rows = participant_rows(st)
    return format_frame(df, fmt), format_rows(columns, rows, fmt)


@pytest.mark.parametrize("fmt", LIST_FORMATS)
def test_lane_keeping_listing_is_unchanged(lk_db, cli, fmt):
    old, new = both(lk_db, fmt)
    assert new == old                                   # no participants yet: "(none)", a header, "[\n\n]"
    with Store.open(lk_db) as st:
        for i, km in enumerate((1000.5, None, 0.1, 123456.789, 0.0, None, 2e-7, 199999.99), start=1):
            add_participant(st, f"LK-{i:02d}", {"age": 20 + 7 * i, "gender": ("female", None, "male")[i % 3],
                                                "km_per_year": km})
        advance(st, "LK-01", "familiarisation", at=DAY)
        advance(st, "LK-02", "familiarisation", at=DAY)
        exclude(st, "LK-02", "objective", "technical_issue")
        exclude(st, "LK-02", "subjective", "other", note="a note")
    old, new = both(lk_db, fmt)
    assert new == old
    assert "-" in old or fmt != "table"                  # missing values were shown
    r = cli("participant", "list", "--format", fmt, db=lk_db)
    assert (r.code, r.out, r.err) == (0, old + "\n", "")


@pytest.mark.parametrize("fmt", LIST_FORMATS)
def test_paper_listing_is_unchanged(paper_db, cli, tmp_path, fmt):
    roster = tmp_path / "roster.csv"
    roster.write_text("participant_id,age,gender,license_years,style,eco_familiarity\n"
                      + "".join(f"P{k:03d},{20 + k},{('female', 'male')[k % 2]},{'' if k % 3 else k % 4},"
                                f"{('normal', 'sporty', '')[k % 3]},{1 + k % 5}\n" for k in range(1, 13)),
                      encoding="utf-8")
    assert cli("participant", "import", roster, db=paper_db).code == 0
    assert cli("session", "advance", "P003", "familiarisation", db=paper_db).code == 0
    assert cli("exclude", "P004", "--scope", "all", "--reason", "withdrawn", db=paper_db).code == 0
    old, new = both(paper_db, fmt)
    assert new == old
    assert cli("participant", "list", "--format", fmt, db=paper_db).out == old + "\n"


def test_a_free_text_attribute_is_listed_as_before(tmp_path, cli):
    """Text with quotes, commas, line breaks, tabs, slashes, non-ASCII and more than 50 characters."""
    folder = tmp_path / "study"
    shutil.copytree(LK_STUDY, folder)
    with open(folder / "study.toml", "a", encoding="utf-8") as f:
        f.write('\n[[attributes]]\nname = "remark"\ntype = "text"\nlabel = "Remark"\n')
    db = tmp_path / "text.duckdb"
    assert cli("init", "--study", folder, db=db).code == 0
    remarks = ['says "hi", twice', "tab\there", "two\nlines\r\nthree", "a/b\\c", "Grüße € 😀", "x" * 61, None,
               "<&>", "\x01control"]
    with Store.open(db) as st:
        for i, text in enumerate(remarks, start=1):
            add_participant(st, f"LK-{i:02d}", {"age": 30 + i, "remark": text})
    for fmt in LIST_FORMATS:
        old, new = both(db, fmt)
        assert new == old, fmt
    assert "x" * 61 in both(db, "table")[1]             # to_string cuts no long text


# ---------------------------------------------------------------------------------------------- random tables
def _floats(rng: random.Random) -> list[float | None]:
    special = [0.0, -0.0, 0.5, 0.05, 2.675, 1e16, 1e16 - 2, 9999999999999998.0, 1e-15, 5e-16, 1e15 + 0.3,
               123456.7890123456, -3.25, 0.99999999999, 1e-5, 1e22, -1e-20, 0.1 + 0.2, 1 / 3, 1e-10 + 5e-11]
    out = []
    for _ in range(rng.randint(1, 8)):
        k = rng.random()
        if k < 0.2:
            out.append(None)
        elif k < 0.5:
            out.append(rng.choice(special))
        elif k < 0.7:
            out.append(round(rng.uniform(-1e6, 1e6), rng.randint(0, 12)))
        else:
            x = struct.unpack("d", struct.pack("Q", rng.getrandbits(64)))[0]
            out.append(x if np.isfinite(x) else None)
    return out


ALPHABET = list("ab z-,.;\"'\\/\n\r\t<&>éß€😀\x01\x1f\x7f0123456789")


def _text(rng: random.Random) -> str | None:
    if rng.random() < 0.15:
        return None
    return "".join(rng.choice(ALPHABET) for _ in range(rng.choice((0, 1, 3, 8, 20, 49, 50, 51, 70))))


def _time(rng: random.Random, mode: str) -> dt.datetime | None:
    if rng.random() < 0.1:
        return None
    t = dt.datetime(2020, 1, 1) + dt.timedelta(days=rng.randint(0, 3000))
    if mode == "date":
        return t
    t += dt.timedelta(seconds=rng.randint(0, 86399))
    return t + dt.timedelta(microseconds={"s": 0, "ms": 1000 * rng.randint(0, 999),
                                          "us": rng.randint(0, 999999)}[mode])


def random_table(rng: random.Random) -> tuple[pd.DataFrame, list[str], list[tuple]]:
    """A DataFrame with the column types of a listing (Int64, float64, object and str text, datetime64[us]) and
    the same values as rows of Python values."""
    n = rng.randint(1, 7)
    frame, columns, values = {}, [], []
    for j in range(rng.randint(1, 6)):
        kind = rng.choice(("int", "float", "object", "str", "time"))
        name = f"{kind}_{j}" + "_long" * rng.choice((0, 0, 12))
        if kind == "int":
            col = [None if rng.random() < 0.2 else rng.choice((rng.randint(-99, 999), rng.randint(-2**62, 2**62)))
                   for _ in range(n)]
            if rng.random() < 0.4:
                col = [0 if v is None else v for v in col]     # no missing value: a numeric column for to_string
            series = pd.Series(col, dtype="Int64")
        elif kind == "float":
            col = (_floats(rng) * n)[:n]
            series = pd.Series([np.nan if v is None else v for v in col], dtype="float64")
        elif kind in ("object", "str"):
            col = [_text(rng) for _ in range(n)]
            series = pd.Series(col, dtype=object if kind == "object" else "str")
            col = [None if v is None else v for v in col]
        else:
            mode = rng.choice(("date", "s", "ms", "us"))
            col = [_time(rng, mode) for _ in range(n)]
            series = pd.Series(pd.to_datetime(col)).astype("datetime64[us]")
        frame[name] = series
        columns.append(name)
        values.append(col)
    return pd.DataFrame(frame), columns, list(zip(*values))


def test_random_tables_print_as_format_frame_prints_them():
    rng = random.Random(20261127)
    for k in range(400):
        df, columns, rows = random_table(rng)
        for fmt in LIST_FORMATS:
            assert format_rows(columns, rows, fmt) == format_frame(df, fmt), (k, fmt, df.dtypes.to_dict())
