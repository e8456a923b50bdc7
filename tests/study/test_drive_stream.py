"""A canonical CSV or Parquet drive log is imported in chunks (study.logs.importing._prepare_file): every problem is the one
the whole log gives, and the stored samples are the ones the whole log gives, whatever the chunk size.

The reference is the whole-log path the same module keeps for mapped logs and frames (`read_drive_file` +
`_prepare`, `import_drive_frame`); the chunk size is set small so that problems fall on chunk borders."""
from __future__ import annotations

import re
import numpy as np
import pandas as pd
import pytest

from study.logs import importing as drives
from study.logs.importing import (_prepare, _prepare_file, _store_drive, DriveRecord, import_drive_file,
                                  import_drive_frame)
from study.logs.stored import drive_samples
from study.logs.reading import read_drive_file
from study.common.errors import UserError
from study.folder.route_file import study_route
from study.store.store import Store
from study.store.studies import definition
from tests.study.test_drive_import import add_participant, make_drive, snapshot

CHUNKS = (1, 2, 7, 64)


def _at(d: pd.DataFrame, col: str, row: int, value) -> pd.DataFrame:
    """`d` with `value` in row `row` of column `col` (unchanged when an earlier mutation dropped the column)."""
    if col not in d.columns:
        return d
    d = d.copy()
    d[col] = d[col].astype(object) if isinstance(value, str) and d[col].dtype != object else d[col]
    d.loc[row, col] = value
    return d


# a problem (or none) at row r of a 200-row log; the CSV-only ones need a text cell in a number column
MUTATIONS = {
    "nan_t": lambda d, r: _at(d, "t", r, np.nan),
    "nan_s": lambda d, r: _at(d, "s", r, np.nan),
    "nan_v": lambda d, r: _at(d, "v", r, np.nan),
    "text_v": lambda d, r: _at(d, "v", r, "fast"),
    "fast": lambda d, r: _at(d, "v", r, 71.0),
    "negative": lambda d, r: _at(d, "v", r, -0.5),
    "kmh_limit": lambda d, r: _at(d, "speed_limit", r, 100.0),
    "same_time": lambda d, r: _at(d, "t", r, d["t"][r - 1]),
    "back_in_time": lambda d, r: _at(d, "t", r, d["t"][r - 1] - 0.05),
    "s_decreases": lambda d, r: _at(d, "s", r, d["s"][r - 1] - 1.0),
    "rural": lambda d, r: _at(d, "segment", r, "rural"),
    "no_segment": lambda d, r: _at(d, "segment", r, ""),
    "blue": lambda d, r: _at(d, "tl_state", r, "blue"),
    "mpc": lambda d, r: _at(d, "controller", r, "mpc"),
    "arrow_2": lambda d, r: _at(d, "hud_arrow", r, 2),
    "maybe": lambda d, r: _at(d, "warning", r, "maybe"),
    "inf_a": lambda d, r: d.assign(a=0.5).pipe(_at, "a", r, np.inf),
    "huge_power": lambda d, r: d.assign(p_batt=1000.0).pipe(_at, "p_batt", r, 5e6),
    "kmh_speed": lambda d, r: d.assign(v=d["v"] * np.where(np.arange(len(d)) >= r, 3.6, 1.0)),
    "gap": lambda d, r: d.assign(t=d["t"] + np.where(np.arange(len(d)) >= r, 30.0, 0.0)),
    "ms": lambda d, r: d.assign(t=d["t"] * 1000.0),
    "no_v": lambda d, r: d.drop(columns="v", errors="ignore"),
    "from_route": lambda d, r: d.drop(columns=["speed_limit", "segment"], errors="ignore"),
    "off_route": lambda d, r: d.drop(columns=["speed_limit", "segment"], errors="ignore").pipe(
        lambda x: x.assign(s=x["s"] + np.where(np.arange(len(x)) >= r, 20_000.0, 0.0))),
    "empty_power": lambda d, r: d.assign(p_batt=np.nan),
    "one_row": lambda d, r: d.iloc[:1],
    "fine": lambda d, r: d,
}
CSV_ONLY = {"text_v", "maybe", "no_segment"}


def _outcome(fn):
    """The problem's message, or what the prepared drive says about the log."""
    try:
        p = fn()
    except UserError as exc:
        return f"refused: {exc}"
    return (p.summary, p.ignored, p.joined, p.overridden)


def _write(df: pd.DataFrame, path, fmt: str):
    if fmt == "csv":
        df.to_csv(path, index=False)
    else:
        df.to_parquet(path, index=False)
    return path


@pytest.fixture(scope="module")
def route():
    from study.folder.definition import load
    from tests.conftest import PAPER_STUDY

    return study_route(load(PAPER_STUDY))


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
@pytest.mark.parametrize("seed", range(16))
def test_problems_are_those_of_the_whole_log(tmp_path, monkeypatch, route, fmt, seed):
    """Random logs with up to three problems at random rows (chunk borders included): the message of the log read
    in chunks is the whole log's, for every chunk size; a log without problems gives the same summary, columns
    from the route and overridden plausibility problems (forced)."""
    rng = np.random.default_rng(seed)
    names = [m for m in MUTATIONS if fmt == "csv" or m not in CSV_ONLY]
    df = make_drive(80, seed=seed)  # longer than the largest chunk: every chunk size splits it
    for name in rng.choice(names, size=rng.integers(0, 4), replace=False):
        df = MUTATIONS[name](df, int(rng.integers(1, len(df)))) if len(df) > 1 else df
    path = _write(df, tmp_path / f"log.{fmt}", fmt)
    for force in (None, "checked"):
        whole = _outcome(lambda: _prepare(read_drive_file(path), None, route, "import", force))
        for n in CHUNKS:
            monkeypatch.setattr(drives, "CHUNK_ROWS", n)
            assert _outcome(lambda: _prepare_file(path, fmt, route, force)) == whole, (n, force)


@pytest.mark.parametrize("name", sorted(set(MUTATIONS) - {"one_row"}))
def test_each_problem_at_a_chunk_border(tmp_path, monkeypatch, route, name):
    """Each problem once, in the first row of a chunk and in the last row of one (chunks of 7 rows), refused or
    imported with --force."""
    monkeypatch.setattr(drives, "CHUNK_ROWS", 7)
    for row, force in ((7, None), (13, None), (7, "checked"), (13, "checked")):
        path = _write(MUTATIONS[name](make_drive(60), row), tmp_path / "log.csv", "csv")
        whole = _outcome(lambda: _prepare(read_drive_file(path), None, route, "import", force))
        assert _outcome(lambda: _prepare_file(path, "csv", route, force)) == whole, (row, force)


def test_a_problem_message_names_the_log_row(tmp_path, monkeypatch, route):
    """Hand-checked: t repeats in data row 15 (the first row of the third chunk of 7: the step across the border);
    v is 71 m/s in row 40."""
    monkeypatch.setattr(drives, "CHUNK_ROWS", 7)
    df = make_drive(60)
    df.loc[14, "t"] = df.loc[13, "t"]
    df.loc[39, "v"] = 71.0
    path = _write(df, tmp_path / "log.csv", "csv")
    with pytest.raises(UserError, match=r"^column v row 40: speed 71 m/s outside 0\.\.70 m/s$"):
        _prepare_file(path, "csv", route, None)     # the speed is checked before the time steps
    df.loc[39, "v"] = 15.0
    _write(df, path, "csv")
    with pytest.raises(UserError, match=r"^column t row 15: time step 0 s is not positive \(t=1\.3 after 1\.3\)$"):
        _prepare_file(path, "csv", route, None)


@pytest.fixture
def st(paper_db):
    with Store.open(paper_db, actor="tester") as s:
        for pid in ("P001", "P002", "P003"):
            add_participant(s, pid)
        yield s


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_stored_samples_are_those_of_the_whole_log(st, tmp_path, monkeypatch, fmt):
    """The paper's study computes a, ft, fb and p_batt (its vehicle model): the samples stored from a log read in
    chunks of 7 rows are exactly those of the same log stored as one frame; so are the drives row's numbers."""
    df = make_drive(300, seed=3)
    df.loc[150:, "t"] += 0.7                         # uneven time steps: the chunk borders must not show in a
    df["s"] = np.concatenate([[0.0], np.cumsum(0.5 * (df["v"].to_numpy()[1:] + df["v"].to_numpy()[:-1])
                                               * np.diff(df["t"].to_numpy()))])
    df["p_batt"] = np.nan                            # an empty power column is no measurement: the model fills it
    path = _write(df, tmp_path / f"log.{fmt}", fmt)
    monkeypatch.setattr(drives, "CHUNK_ROWS", 7)
    streamed = import_drive_file(st, "P001", "baseline", path)
    whole = import_drive_frame(st, "P002", "baseline", read_drive_file(path), source="import")
    assert (streamed.n_samples, streamed.filled_columns, streamed.energy_source) == (
        whole.n_samples, whole.filled_columns, whole.energy_source) == (300, ("a", "ft", "fb", "p_batt"),
                                                                         "modelled (Nissan Leaf parameters)")
    a, b = drive_samples(st, "P001", "baseline"), drive_samples(st, "P002", "baseline")
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    np.testing.assert_array_equal(a["a"], np.gradient(df["v"].to_numpy(), df["t"].to_numpy()))
    rows = st.df("SELECT n_samples, duration_s, distance_m FROM drives ORDER BY participant_id")
    assert rows.iloc[0].tolist() == rows.iloc[1].tolist()
    assert st.one("SELECT min(idx) FROM drive_samples") == 0 and st.one("SELECT max(idx) FROM drive_samples") == 299


def test_cli_import_in_chunks_then_export(cli, paper_db, tmp_path, monkeypatch):
    """End to end: `drive import` of a 1000-row CSV in chunks of 64 rows, its samples in the export as imported."""
    with Store.open(paper_db) as s:
        add_participant(s, "P001")
    df = make_drive(1000, seed=5)
    path = _write(df, tmp_path / "log.csv", "csv")
    monkeypatch.setattr(drives, "CHUNK_ROWS", 64)
    r = cli("drive", "import", "P001", "baseline", path, "-v")
    assert r.code == 0 and "imported drive 1, 1000 samples" in r.out and "read 1000 rows from log.csv" in r.err
    assert cli("export", "parquet", tmp_path / "out").code == 0
    back = pd.read_parquet(tmp_path / "out" / "drive_samples.parquet")
    assert back["idx"].tolist() == list(range(1000))
    np.testing.assert_array_equal(back["v"], df["v"])
    assert back["segment"].tolist() == df["segment"].tolist()


def test_a_file_changed_between_the_two_reads_stores_nothing(st, tmp_path, monkeypatch, paper_db):
    """The log is read twice (checked, then stored); a file that changed in between is refused in the store's
    transaction, which leaves the store as it was."""
    monkeypatch.setattr(drives, "CHUNK_ROWS", 16)
    path = _write(make_drive(100), tmp_path / "log.csv", "csv")
    prep = _prepare_file(path, "csv", study_route(definition(st)), None)
    assert prep.frame is None and prep.summary.n == 100   # nothing of the log is kept but its summary
    _write(make_drive(100).assign(v=lambda d: d["v"].where(d.index != 50, 99.0)), path, "csv")
    before = st.counts()
    record = DriveRecord("P001", "baseline", prep, "0" * 64, "import", 0.0, file_name=path.name)
    with pytest.raises(UserError, match="log.csv changed while it was being imported: column v row 51: speed 99"):
        _store_drive(st, record)
    _write(make_drive(120), path, "csv")
    with pytest.raises(UserError, match=re.escape(str(path)) + " changed while it was being imported$"):
        _store_drive(st, record)
    assert st.counts() == before


def test_unreadable_file_is_one_line(cli, paper_db, tmp_path):
    with Store.open(paper_db) as s:
        add_participant(s, "P001")
    before = snapshot(paper_db)
    bad = tmp_path / "log.parquet"
    bad.write_bytes(b"not parquet at all")
    r = cli("drive", "import", "P001", "baseline", bad)
    assert r.code == 2 and r.err.startswith(f"pedas-study: error: cannot read {bad}: ") and r.out == ""
    assert len(r.err.strip().splitlines()) == 1 and snapshot(paper_db) == before
