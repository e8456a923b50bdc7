"""Drive-log validation and import of canonical logs (the paper's study): CSV/Parquet, checksums, idempotency,
--replace, bad input. Mapped logs, routes, extra channels and FCD: tests/study/test_drive_mapping.py."""
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st_

from study.folder.drive_columns import COLUMNS
from study.logs.stored import drive_samples
from study.logs.reading import frame_checksum
from study.logs.importing import import_drive_file, import_drive_frame
from study.logs.validation import validate_drive
from study.common.errors import UserError
from study.store.store import Store


def add_participant(st, pid):
    """Register a participant row (the drive import only needs it to exist)."""
    from study.store.studies import definition

    st.insert("participants", {"participant_id": pid, "protocol": definition(st).protocol().name})


def make_drive(n=500, seed=0, dt=0.1):
    """A plausible drive log: noisy cruise at ~15 m/s, urban first half, highway second half."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    v = np.clip(15 + np.cumsum(rng.normal(0, 0.05, n)), 0, 40)
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * dt)])
    seg = np.where(np.arange(n) < n // 2, "urban", "highway")
    return pd.DataFrame({"t": t, "s": s, "v": v, "segment": seg,
                         "speed_limit": np.where(seg == "urban", 13.89, 33.33),
                         "tl_state": np.where(rng.random(n) < 0.5, "green", "red"),
                         "controller": "rt", "hud_arrow": rng.integers(-1, 2, n),
                         "warning": rng.random(n) < 0.05})


def snapshot(db):
    """Everything a refused operation must leave unchanged: each table's row count and the full audit log."""
    with Store.open(db) as st:
        return st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")


@pytest.fixture
def st(paper_db):
    with Store.open(paper_db, actor="tester") as s:
        add_participant(s, "P001")
        add_participant(s, "P002")
        yield s


def test_import_csv_roundtrip(st, tmp_path):
    df = make_drive(300)
    path = tmp_path / "p1_baseline.csv"
    df.to_csv(path, index=False)
    r = import_drive_file(st, "P001", "baseline", path)
    assert r.status == "imported" and r.n_samples == 300
    back = drive_samples(st, "P001", "baseline")
    assert list(back.columns) == list(COLUMNS)
    np.testing.assert_allclose(back["v"], df["v"], rtol=0, atol=1e-12)
    assert back["segment"].tolist() == df["segment"].tolist()
    assert back["warning"].astype(bool).tolist() == df["warning"].tolist()
    assert back["hud_arrow"].astype(int).tolist() == df["hud_arrow"].tolist()
    row = st.df("SELECT * FROM drives").iloc[0]
    assert row["file_name"] == "p1_baseline.csv" and row["source"] == "import"
    assert row["duration_s"] == pytest.approx(29.9) and row["distance_m"] == pytest.approx(df["s"].iloc[-1])
    # the drive is audited once, at the drive level, not per sample
    assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'drives'") == 1
    assert st.one("SELECT count(*) FROM audit_log WHERE table_name = 'drive_samples'") == 0


def test_computed_columns_filled(st, tmp_path):
    pytest.importorskip("pedas.power")
    path = tmp_path / "d.parquet"
    make_drive(200).to_parquet(path)
    r = import_drive_file(st, "P001", "pedas", path)
    assert {"a", "ft", "fb", "p_batt"} <= set(r.filled_columns)
    back = drive_samples(st, "P001", "pedas")
    assert back[["a", "ft", "fb", "p_batt"]].notna().all().all()
    np.testing.assert_allclose(back["a"], np.gradient(back["v"], back["t"]), atol=1e-9)


def test_present_optional_columns_kept(st):
    df = make_drive(100).assign(a=0.25)
    import_drive_frame(st, "P001", "baseline", df)
    assert (drive_samples(st, "P001", "baseline")["a"] == 0.25).all()


def test_reimport_same_file_is_idempotent(st, tmp_path):
    path = tmp_path / "d.parquet"
    make_drive().to_parquet(path)
    first = import_drive_file(st, "P001", "baseline", path)
    before = st.counts()
    again = import_drive_file(st, "P001", "baseline", path)
    assert again.status == "unchanged" and again.drive_id == first.drive_id
    assert st.counts() == before


def test_different_file_needs_replace(st, tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    make_drive(300, seed=1).to_csv(a, index=False)
    make_drive(400, seed=2).to_csv(b, index=False)
    import_drive_file(st, "P001", "baseline", a)
    before = st.counts()
    with pytest.raises(UserError, match="already has a baseline drive from a.csv.*--replace"):
        import_drive_file(st, "P001", "baseline", b)
    assert st.counts() == before
    r = import_drive_file(st, "P001", "baseline", b, replace=True)
    assert r.status == "replaced"
    assert st.one("SELECT count(*) FROM drive_samples") == 400
    assert st.one("SELECT n_samples FROM drives") == 400
    log = st.df("SELECT action FROM audit_log WHERE table_name = 'drives' ORDER BY audit_id")
    assert log["action"].tolist() == ["insert", "delete", "insert"]


def test_same_file_for_another_participant_refused(st, tmp_path):
    path = tmp_path / "d.csv"
    make_drive().to_csv(path, index=False)
    import_drive_file(st, "P001", "baseline", path)
    with pytest.raises(UserError, match="already stored as the baseline drive of P001"):
        import_drive_file(st, "P002", "baseline", path)


def test_frame_import_and_checksum(st):
    df = make_drive(250)
    r = import_drive_frame(st, "P001", "pedas", df, source="simulation", route="paper_route", seed=7,
                           meta={"style": "normal"})
    assert r.status == "imported"
    assert import_drive_frame(st, "P001", "pedas", df.copy(), seed=7).status == "unchanged"
    row = st.df("SELECT source, route, seed, meta FROM drives").iloc[0]
    # the caller's settings, plus where the energy comes from: the frame has no p_batt, the paper's study
    # declares the vehicle model
    assert (row["source"], row["route"], row["seed"], row["meta"]) == (
        "simulation", "paper_route", 7, '{"energy_source": "modelled (Nissan Leaf parameters)", "style": "normal"}')
    df2 = df.copy()
    df2.loc[10, "v"] += 1e-9
    assert frame_checksum(validate_drive(df2)[0]) != frame_checksum(validate_drive(df)[0])


@pytest.mark.parametrize("mutate, msg", [
    (lambda d: d.drop(columns="v"), "missing required column 'v'"),
    (lambda d: d.drop(columns="segment"), "missing required column 'segment'"),
    (lambda d: d.assign(v=d["v"].where(d.index != 7)), "column v row 8: missing value"),
    (lambda d: d.assign(v=d["v"].where(d.index != 3, 71.0)), "column v row 4: speed 71 m/s outside"),
    (lambda d: d.assign(v=d["v"].where(d.index != 3, -0.5)), "column v row 4: speed -0.5 m/s outside"),
    (lambda d: d.assign(t=d["t"].where(d.index != 5, 0.3)), "column t row 6: time step -0.1 s is not positive"),
    (lambda d: d.assign(t=d["t"].where(d.index != 5, 0.4)), "column t row 6: time step 0 s"),
    (lambda d: d.assign(s=d["s"].where(d.index != 9, 0.0)), "column s row 10: distance decreases"),
    (lambda d: d.assign(segment=d["segment"].where(d.index != 2, "rural")), "column segment row 3: 'rural'"),
    (lambda d: d.assign(speed_limit=50.0 + 0 * d["v"]).assign(speed_limit=lambda x: x["speed_limit"].where(
        x.index != 0, 100.0)), "column speed_limit row 1: 100 m/s"),
    (lambda d: d.assign(tl_state=d["tl_state"].where(d.index != 4, "blue")), "column tl_state row 5"),
    (lambda d: d.assign(controller="mpc"), "column controller row 1"),
    (lambda d: d.assign(hud_arrow=2), "column hud_arrow row 1: 2 is not one of"),
    (lambda d: d.assign(warning="maybe"), "column warning row 1"),
    (lambda d: d.iloc[:1], "at least 2 samples"),
])
def test_validation_names_first_problem(mutate, msg):
    with pytest.raises(UserError, match=msg.replace("(", r"\(").replace("+", r"\+")):
        validate_drive(mutate(make_drive(50)), segments=("urban", "highway"))


def test_segment_labels_are_free_without_a_route():
    out, _ = validate_drive(make_drive(50).assign(segment="rural"))
    assert set(out["segment"]) == {"rural"}
    with pytest.raises(UserError, match="column segment row 1: 'xxxxx.*longer than 64"):
        validate_drive(make_drive(50).assign(segment="x" * 65))


def test_csv_text_in_numeric_column(tmp_path):
    path = tmp_path / "d.csv"
    make_drive(20).to_csv(path, index=False)
    lines = path.read_text().splitlines()
    cells = lines[4].split(",")
    cells[2] = "fast"
    lines[4] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    from study.logs.reading import read_drive_file
    with pytest.raises(UserError, match="column v row 4: 'fast' is not a number"):
        validate_drive(read_drive_file(path))


@settings(max_examples=25, deadline=None)
@given(st_.integers(min_value=2, max_value=300), st_.integers(min_value=0, max_value=10_000))
def test_valid_logs_pass_and_keep_values(n, seed):
    """Any monotone, in-range log passes validation unchanged (property)."""
    df = make_drive(n, seed)
    out, ignored = validate_drive(df.assign(extra_col=1))
    assert ignored == ("extra_col",)
    np.testing.assert_array_equal(out["t"].to_numpy(), df["t"].to_numpy())
    np.testing.assert_array_equal(out["v"].to_numpy(), df["v"].to_numpy())


# ------------------------------------------------------------------------ bad input through the CLI
BAD_LOGS = {
    "nan_speed": lambda d: d.assign(v=d["v"].where(d.index != 17)),
    "negative_time_step": lambda d: d.assign(t=d["t"].where(d.index != 30, d["t"][29] - 0.05)),
    "missing_column": lambda d: d.drop(columns="v"),  # speed_limit and segment would come from the route
    "wrong_segment": lambda d: d.assign(segment=d["segment"].where(d.index != 40, "motorway")),
}


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
@pytest.mark.parametrize("case", sorted(BAD_LOGS))
def test_cli_bad_log_changes_nothing(cli, paper_db, tmp_path, case, fmt):
    tmp_db = paper_db
    with Store.open(tmp_db) as s:
        add_participant(s, "P001")
    good = tmp_path / f"good.{fmt}"
    bad = tmp_path / f"bad.{fmt}"
    df = make_drive(100)
    for path, frame in ((good, df), (bad, BAD_LOGS[case](df))):
        frame.to_csv(path, index=False) if fmt == "csv" else frame.to_parquet(path)
    assert cli("drive", "import", "P001", "baseline", good).code == 0
    before = snapshot(tmp_db)
    for cond, extra in (("pedas", ()), ("baseline", ("--replace",))):
        r = cli("drive", "import", "P001", cond, bad, *extra)
        assert r.code != 0
        lines = r.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("pedas-study: error: ")
        assert snapshot(tmp_db) == before


def test_cli_import_messages(cli, paper_db, tmp_path):
    with Store.open(paper_db) as s:
        add_participant(s, "P001")
    path = tmp_path / "d.csv"
    make_drive(100).to_csv(path, index=False)
    r = cli("drive", "import", "P001", "baseline", path)
    assert r.code == 0 and "imported drive 1, 100 samples" in r.out
    assert "unchanged" in cli("drive", "import", "P001", "baseline", path).out
    r = cli("drive", "import", "P009", "baseline", path)
    assert r.code == 2 and "unknown participant P009" in r.err
    r = cli("drive", "import", "P001", "baseline", tmp_path / "none.csv")
    assert r.code == 2 and "no such file" in r.err
    (tmp_path / "d.xlsx").write_text("x")
    assert "unknown drive log format" in cli("drive", "import", "P001", "pedas", tmp_path / "d.xlsx").err
    r = cli("drive", "list", "--format", "csv")
    assert r.out.splitlines()[1].startswith("1,P001,baseline,import")


def test_a_file_name_is_shown_as_given_with_its_control_characters_escaped(cli, paper_db, tmp_path):
    """A stray CR from a file list (logs/P001.csv\\r) is shown, not hidden as a space, with the folder given."""
    with Store.open(paper_db) as s:
        add_participant(s, "P001")
    path = tmp_path / "logs" / "P001_baseline.csv\r"
    path.parent.mkdir()
    path.write_text("x")
    r = cli("drive", "import", "P001", "baseline", path)
    assert r.code == 2 and r.err == (f"pedas-study: error: {tmp_path}/logs/P001_baseline.csv\\r: unknown drive log "
                                     "format (use .csv, .parquet or SUMO FCD .xml, or --format)\n")
