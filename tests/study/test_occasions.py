"""Questionnaire occasions and drives outside conditions: a within-subjects takeover study (18 participants
TOR-A01…, warnings none / visual / audiovisual in a Latin square, a familiarisation drive, the same post-drive
questionnaire after each drive and a final one), built from the seed data of tests/data/takeover/items.csv.

Reference numbers: the answers of items.csv itself (what is imported comes back item for item) and the SUS scores of
tests/data/takeover/scores.csv (computed there independently; SUS = 2.5 x (sum of odd items - 5 + 25 - sum of even
items)).
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pytest

from study.store import migrate
from study.store.store import Store

DATA = Path(__file__).parents[1] / "data" / "takeover"
ORDERS = {"none-visual-audiovisual": ["none", "visual", "audiovisual"],
          "visual-audiovisual-none": ["visual", "audiovisual", "none"],
          "audiovisual-none-visual": ["audiovisual", "none", "visual"]}
SUS = [f"sus{k}" for k in range(1, 11)]
TLX = ["tlx_mental", "tlx_physical", "tlx_temporal", "tlx_performance", "tlx_effort", "tlx_frustration"]
TRUST = [f"trust{k}" for k in range(1, 7)]
ITEMS = SUS + TLX + TRUST

STUDY_TOML = """\
[study]
id = "takeover"
title = "Takeover warnings"

[participants]
id_pattern = "^TOR-A[0-9]{2}$"
id_example = "TOR-A01"

[[conditions]]
name = "none"
[[conditions]]
name = "visual"
[[conditions]]
name = "audiovisual"

[files]
instrument = ["post_drive.csv", "final.csv"]
protocols = ["protocol.json"]
"""
HEADER = "item_id,construct,section,text,response_type,scale_min,scale_max,anchor_low,anchor_high,choices," \
         "reverse_scored,required\n"


def _codebooks() -> tuple[str, str]:
    rows = [f"{i},SUS,Usability,SUS statement {i[3:]},likert5,1,5,Strongly disagree,Strongly agree,,0,1" for i in SUS]
    rows += [f"{i},TLX,Workload,{i[4:]} demand,number,0,100,,,,0,1" for i in TLX]
    rows += [f"{i},TRUST,Trust,Trust statement {i[5:]},likert7,1,7,Not at all,Completely,,0,1" for i in TRUST]
    final = HEADER + "PREF,PREF,Preference,Which warning did you prefer?,choice,1,3,,,1=none|2=visual|3=audiovisual,0,1\n"
    return HEADER + "\n".join(rows) + "\n", final


def _protocol() -> dict:
    phases = [{"name": "familiarisation", "planned_minutes": 10, "drive": True, "condition": None}]
    for c in ("none", "visual", "audiovisual"):
        phases += [{"name": f"drive_{c}", "planned_minutes": 8, "drive": True, "condition": c},
                   {"name": f"survey_after_{c}", "planned_minutes": 5, "instrument": "post_drive", "rates": c}]
    phases.append({"name": "final", "planned_minutes": 5, "instrument": "final"})
    orders = {name: ["familiarisation"] + [p for c in seq for p in (f"drive_{c}", f"survey_after_{c}")] + ["final"]
              for name, seq in ORDERS.items()}
    return {"name": "latin_square", "phases": phases, "orders": orders}


def write_study(folder: Path, protocol: dict | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    post, final = _codebooks()
    (folder / "study.toml").write_text(STUDY_TOML, encoding="utf-8")
    (folder / "post_drive.csv").write_text(post, encoding="utf-8")
    (folder / "final.csv").write_text(final, encoding="utf-8")
    (folder / "protocol.json").write_text(json.dumps(protocol or _protocol(), indent=1), encoding="utf-8")
    return folder


def seed() -> pd.DataFrame:
    return pd.read_csv(DATA / "items.csv")


@pytest.fixture
def tor(cli, tmp_path):
    """A store of the takeover study with the participants of items.csv registered."""
    assert cli("init", "--study", write_study(tmp_path / "takeover")).code == 0
    roster = tmp_path / "roster.csv"
    pd.DataFrame({"participant_id": sorted(seed()["participant"].unique())}).to_csv(roster, index=False)
    assert cli("participant", "import", roster).code == 0
    return cli


def _wide_file(path: Path, which: str = "condition") -> Path:
    df = seed()
    df["occasion"] = "survey_after_" + df["condition"]
    df = df.rename(columns={"participant": "participant_id"})[["participant_id", which] + ITEMS]
    df.to_csv(path, index=False)
    return path


# ---------------------------------------------------------------------------------------------- study check
def test_the_takeover_study_checks_and_lists_its_occasions(tmp_path):
    from study.folder.definition import check, load
    from study.folder.occasions import study_occasions

    d = write_study(tmp_path / "takeover")
    assert check(d) == []
    study = load(d)
    assert list(study.instruments) == ["post_drive_v1", "final_v1"]
    assert [(o.name, o.instrument, o.rates) for o in study_occasions(study)] == [
        ("survey_after_none", "post_drive_v1", "none"), ("survey_after_visual", "post_drive_v1", "visual"),
        ("survey_after_audiovisual", "post_drive_v1", "audiovisual"), ("final", "final_v1", None)]


@pytest.mark.parametrize("change, message", [
    (lambda p: p["phases"][2].update(instrument="post"), "phases.survey_after_none.instrument: 'post' is not an "
                                                         "instrument of the study (post_drive, final)"),
    (lambda p: p["phases"][2].update(rates="auditory"), "phases.survey_after_none.rates: 'auditory' is not a "
                                                        "declared condition (none|visual|audiovisual)"),
    (lambda p: p["orders"]["none-visual-audiovisual"].insert(1, p["orders"]["none-visual-audiovisual"].pop(2)),
     "phases.survey_after_none.rates: rates none but comes before any drive in order none-visual-audiovisual"),
    (lambda p: p["phases"][4].update(rates="none"), "phases.survey_after_visual.rates: rates none but the drive "
                                                    "before it in order none-visual-audiovisual is drive_visual "
                                                    "(visual)"),
    (lambda p: p["phases"][0].update(instrument="final"), "phases.familiarisation.instrument: a drive phase cannot "
                                                          "be a questionnaire phase"),
])
def test_study_check_refuses_bad_questionnaire_phases(tmp_path, change, message):
    from study.folder.definition import check

    proto = _protocol()
    change(proto)
    problems = [str(p) for p in check(write_study(tmp_path / "t", proto))]
    assert any(message in p for p in problems), problems


# ---------------------------------------------------------------------------------------------- import and final
@pytest.mark.parametrize("which", ["condition", "occasion"])
def test_a_wide_file_with_a_condition_or_occasion_column_imports_every_occasion(tor, tmp_path, which):
    r = tor("survey", "import", _wide_file(tmp_path / "wide.csv", which))
    assert r.code == 0, r.err
    assert r.out.strip() == ("imported 19 participants at 3 occasions (survey_after_none, survey_after_visual, "
                             "survey_after_audiovisual; 56 questionnaires) (1232 answers, 0 missing) as single "
                             "electronic entry (final)")
    out = tmp_path / "final.csv"
    r = tor("survey", "final", "--instrument", "post_drive", "--out", out)
    assert r.code == 0 and r.out.strip() == f"wrote 56 rows (19 participants) to {out}"
    final = pd.read_csv(out)
    assert list(final.columns[:3]) == ["participant_id", "occasion", "condition"] and list(final.columns[3:]) == ITEMS
    want = seed().rename(columns={"participant": "participant_id"})
    got = final.merge(want, on=["participant_id", "condition"], suffixes=("", "_seed"))
    assert len(got) == 56 and (got[ITEMS].to_numpy() == got[[f"{i}_seed" for i in ITEMS]].to_numpy()).all()
    # rows per participant in the protocol's occasion order, whatever order the participant answered in
    assert final.loc[final["participant_id"] == "TOR-A02", "occasion"].tolist() == [
        "survey_after_none", "survey_after_visual", "survey_after_audiovisual"]
    # the SUS score from the stored answers is scores.csv's
    odd, even = final[SUS[0::2]].sum(axis=1), final[SUS[1::2]].sum(axis=1)
    final["sus"] = 2.5 * ((odd - 5) + (25 - even))
    ref = pd.read_csv(DATA / "scores.csv").rename(columns={"participant": "participant_id"})
    both = final.merge(ref, on=["participant_id", "condition"], suffixes=("", "_ref"))
    assert len(both) == 56 and np.allclose(both["sus"], both["sus_ref"], atol=0)
    # one occasion, in the format of a study without occasions
    r = tor("survey", "final", "--occasion", "survey_after_visual", "--out", out)
    assert r.code == 0 and r.out.strip() == f"wrote 19 participants to {out}"
    assert list(pd.read_csv(out).columns) == ["participant_id"] + ITEMS


def test_a_survey_file_s_own_columns_are_left_out_with_ignore_columns(tor, tmp_path):
    wide = pd.read_csv(_wide_file(tmp_path / "wide.csv"))
    wide.insert(1, "position", range(len(wide)))      # the lab's own bookkeeping beside the items
    wide.to_csv(tmp_path / "own.csv", index=False)
    r = tor("survey", "import", tmp_path / "own.csv")
    assert r.code == 2 and "unknown item column(s) position for instrument post_drive" in r.err
    r = tor("survey", "import", tmp_path / "own.csv", "--ignore-columns", "position,seat")
    assert r.code == 2 and r.err.strip().endswith("own.csv: --ignore-columns names no column of the file: seat "
                                                  f"(the columns are {', '.join(wide.columns)})")
    r = tor("survey", "import", tmp_path / "own.csv", "--ignore-columns", "position")
    assert r.code == 0 and r.out.startswith("imported 19 participants at 3 occasions"), r.err


def test_a_long_file_gives_the_same_answers_as_the_wide_one(tor, cli, tmp_path):
    wide = seed().rename(columns={"participant": "participant_id"})
    wide["occasion"] = "survey_after_" + wide["condition"]
    long = wide.melt(id_vars=["participant_id", "occasion"], value_vars=ITEMS, var_name="item_id")
    long.sample(frac=1.0, random_state=7).to_csv(tmp_path / "long.csv", index=False)   # any row order
    r = tor("survey", "import", tmp_path / "long.csv")
    assert r.code == 0 and "imported 19 participants at 3 occasions" in r.out, r.err
    r = tor("survey", "final", "--instrument", "post_drive", "--out", tmp_path / "f.csv")
    final = pd.read_csv(tmp_path / "f.csv").set_index(["participant_id", "occasion"])[ITEMS]
    assert final.sort_index().equals(wide.set_index(["participant_id", "occasion"])[ITEMS].sort_index())


def _counts(db: Path) -> dict:
    with Store.open(db, read_only=True) as st:
        return {**st.counts(), "audit": st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")}


@pytest.mark.parametrize("edit, message", [
    (lambda df: df.assign(condition=df["condition"].where(df.index != 4, "auditory")),
     "wide.csv: line 6: TOR-A02: condition 'auditory' is rated by no occasion of instrument post_drive_v1 "
     "(rated: audiovisual, none, visual); nothing imported"),
    (lambda df: pd.concat([df, df.iloc[[0]]]),
     "wide.csv: line 58: duplicate participant TOR-A01 at condition none (also on line 2); nothing imported"),
    (lambda df: df.drop(columns="condition"),
     "wide.csv: instrument post_drive_v1 is answered on 3 occasions (survey_after_none, survey_after_visual, "
     "survey_after_audiovisual): name one with --occasion or an occasion or condition column in the file"),
])
def test_bad_occasion_columns_are_refused_in_one_line_and_nothing_is_stored(tor, tmp_db, tmp_path, edit, message):
    path = _wide_file(tmp_path / "wide.csv")
    edit(pd.read_csv(path)).to_csv(path, index=False)
    before = _counts(tmp_db)
    r = tor("survey", "import", path, "--instrument", "post_drive")
    assert r.code == 2 and r.err.strip() == f"pedas-study: error: {tmp_path}/{message}"
    assert _counts(tmp_db) == before


def test_answers_already_stored_for_one_occasion_do_not_block_another(tor, tmp_path):
    path = _wide_file(tmp_path / "wide.csv")
    df = pd.read_csv(path)
    df[df["condition"] == "none"].to_csv(tmp_path / "none.csv", index=False)
    df[df["condition"] != "none"].to_csv(tmp_path / "rest.csv", index=False)
    assert tor("survey", "import", tmp_path / "none.csv").code == 0
    r = tor("survey", "import", tmp_path / "none.csv")
    assert r.code == 2 and "line 2: TOR-A01 already has answers at survey_after_none (import by" in r.err
    assert tor("survey", "import", tmp_path / "rest.csv").code == 0


def test_double_entry_and_resolution_carry_the_occasion(tor, tmp_path):
    one = pd.read_csv(_wide_file(tmp_path / "w.csv", "occasion")).head(2)   # TOR-A01 at none and visual
    one.to_csv(tmp_path / "e1.csv", index=False)
    two = one.copy()
    two.loc[1, "sus1"] = 1
    two.to_csv(tmp_path / "e2.csv", index=False)
    assert tor("survey", "import", tmp_path / "e1.csv", "--entry", "1").code == 0
    assert tor("survey", "import", tmp_path / "e2.csv", "--entry", "2").code == 0
    d = json.loads(tor("survey", "discrepancies", "--instrument", "post_drive", "--format", "json").out)
    assert [(x["participant_id"], x["occasion"], x["item_id"], x["value_1"], x["value_2"]) for x in d] == [
        ("TOR-A01", "survey_after_visual", "sus1", 5, 1)]
    r = tor("survey", "resolve", "TOR-A01", "sus1", "5", "--instrument", "post_drive")
    assert r.code == 2 and "answered on 3 occasions" in r.err
    r = tor("survey", "resolve", "TOR-A01", "sus1", "5", "--occasion", "survey_after_none")
    assert r.code == 2 and "no discrepancy between the two entries to resolve at survey_after_none" in r.err
    assert tor("survey", "resolve", "TOR-A01", "sus1", "5", "--occasion", "survey_after_visual").code == 0
    status = json.loads(tor("survey", "status", "--instrument", "post_drive", "--format", "json").out)
    mine = {(s["occasion"]): s["basis"] for s in status if s["participant_id"] == "TOR-A01"}
    assert mine == {"survey_after_none": "double_entry_final", "survey_after_visual": "double_entry_final",
                    "survey_after_audiovisual": "none"}


# ---------------------------------------------------------------------------------------------- links
def test_one_link_per_questionnaire_phase(tor, tmp_db):
    from study.survey import answers as sv

    r = tor("survey", "link", "TOR-A01", "--instrument", "post_drive")
    assert r.code == 2 and r.err.strip() == (
        "pedas-study: error: instrument post_drive_v1 is answered on 3 occasions (survey_after_none, "
        "survey_after_visual, survey_after_audiovisual): name one with --occasion")
    for phase in ("familiarisation", "drive_none", "survey_after_none"):   # TOR-A01's order starts with none
        assert tor("session", "advance", "TOR-A01", phase).code == 0, phase
    url = tor("survey", "link", "TOR-A01", "--instrument", "post_drive").out.strip()   # the phase it is in
    final_url = tor("survey", "link", "TOR-A01", "--occasion", "final").out.strip()
    with Store.open(tmp_db) as st:
        a, b = (sv.resolve_token(st, u.rsplit("/", 1)[1]) for u in (url, final_url))
        assert (a.instrument, a.occasion, b.instrument, b.occasion) == (
            "post_drive_v1", "survey_after_none", "final_v1", "final")
        answers = seed().iloc[0][ITEMS].to_dict()
        sv.save_draft(st, "TOR-A01", answers, a.instrument, a.occasion)
        assert sv.submit_web(st, "TOR-A01", a.instrument, a.occasion) == 22
        assert sv.resolve_token(st, url.rsplit("/", 1)[1]).submitted
        assert not sv.resolve_token(st, final_url.rsplit("/", 1)[1]).submitted   # the other link is untouched


# ---------------------------------------------------------------------------------------------- exports
def test_exports_carry_the_occasion_also_deidentified(tor, tmp_path):
    assert tor("survey", "import", _wide_file(tmp_path / "wide.csv")).code == 0
    for flag in ([], ["--deidentify"]):
        out = tmp_path / f"csv{len(flag)}"
        assert tor("export", "csv", out, *flag).code == 0
        resp = pd.read_csv(out / "responses.csv")
        assert "occasion" in resp.columns and set(resp["occasion"]) == {
            "survey_after_none", "survey_after_visual", "survey_after_audiovisual"}
        wide = pd.read_csv(out / "survey_wide_post_drive_v1.csv")
        assert list(wide.columns[:3]) == ["participant_id", "occasion", "condition"] and len(wide) == 56
        assert "occasion" in pd.read_csv(out / "survey_submissions.csv").columns


def test_a_study_with_one_occasion_exports_no_occasion_column(cli, paper_db, tmp_path):
    assert cli("participant", "add", "P001").code == 0
    assert cli("survey", "link", "P001").code == 0
    assert cli("export", "csv", tmp_path / "out").code == 0
    for table in ("responses", "survey_tokens", "survey_submissions", "survey_drafts", "survey_resolutions"):
        assert "occasion" not in pd.read_csv(tmp_path / "out" / f"{table}.csv").columns, table
    assert "phase" not in pd.read_csv(tmp_path / "out" / "drives.csv").columns
    with Store.open(paper_db, read_only=True) as st:
        assert st.one("SELECT occasion FROM survey_tokens") == "survey"


# ---------------------------------------------------------------------------------------------- drives
def _log(path: Path, seed_: int, n: int = 200) -> Path:
    rng = np.random.default_rng(seed_)
    t = np.arange(n) * 0.1
    v = np.clip(30 + np.cumsum(rng.normal(0, 0.05, n)), 0, 40)
    s = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1)])
    pd.DataFrame({"t": t, "s": s, "v": v, "segment": "motorway", "speed_limit": 36.1}).to_csv(path, index=False)
    return path


def test_a_familiarisation_drive_is_stored_outside_the_conditions(tor, tmp_db, tmp_path):
    assert tor("session", "advance", "TOR-A01", "familiarisation").code == 0
    r = tor("drive", "import", "TOR-A01", "familiarisation", _log(tmp_path / "fam.csv", 1))
    assert r.code == 0 and r.out.startswith("TOR-A01 familiarisation: imported drive 1, 200 samples"), r.err
    listing = json.loads(tor("drive", "list", "--format", "json").out)
    assert [(d["condition"], d["phase"]) for d in listing] == [(None, "familiarisation")]
    r = tor("drive", "import", "TOR-A01", "warmup", tmp_path / "fam.csv")
    assert r.code == 2 and r.err.strip() == ("pedas-study: error: unknown condition 'warmup' (study takeover: "
                                             "none|visual|audiovisual; drive phases without a condition: "
                                             "familiarisation)")


def test_a_log_of_a_drive_entered_imports_after_the_fact_and_one_not_entered_is_refused_unless_forced(
        tor, tmp_db, tmp_path):
    for phase in ("familiarisation", "drive_none", "survey_after_none", "drive_visual"):
        assert tor("session", "advance", "TOR-A01", phase).code == 0
    # the none drive is over and the participant is in the next drive: its log is copied afterwards
    assert tor("drive", "import", "TOR-A01", "none", _log(tmp_path / "none.csv", 2)).code == 0
    assert tor("drive", "import", "TOR-A01", "familiarisation", _log(tmp_path / "fam.csv", 4)).code == 0
    # a second, different log of the same drive still needs --replace
    r = tor("drive", "import", "TOR-A01", "none", _log(tmp_path / "none2.csv", 5))
    assert r.code == 2 and "already has a none drive from none.csv with different content; use --replace" in r.err
    assert tor("session", "abort", "TOR-A01", "--reason", "motion sickness").code == 0
    log = _log(tmp_path / "av.csv", 6)
    before = _counts(tmp_db)
    r = tor("drive", "import", "TOR-A01", "audiovisual", log)
    expected = ("TOR-A01 has not entered the drive of audiovisual (drive_audiovisual); phases entered: "
                "familiarisation, drive_none, survey_after_none, drive_visual (aborted)")
    assert r.code == 2 and r.err.strip() == (
        f"pedas-study: error: {expected}; import with --force REASON to store it anyway")
    assert _counts(tmp_db) == before
    r = tor("drive", "import", "TOR-A01", "audiovisual", log, "--force", "log of a drive the protocol did not record")
    assert r.code == 0, r.err
    assert f"note: imported with --force despite: {expected}" in r.err
    with Store.open(tmp_db, read_only=True) as st:
        new = [json.loads(n) for n in st.df("SELECT new FROM audit_log WHERE table_name = 'drives' "
                                            "AND action = 'insert' ORDER BY audit_id")["new"]]
    assert json.loads(new[-1]["meta"])["forced"] == {"reason": "log of a drive the protocol did not record",
                                                     "overridden": [expected]}
    # the drive aborted (entered) takes its log without --force
    assert tor("drive", "import", "TOR-A01", "visual", _log(tmp_path / "visual.csv", 3)).code == 0


# ---------------------------------------------------------------------------------------------- migration
def test_a_store_of_the_schema_before_occasions_keeps_its_answers(tmp_db, tmp_path):
    """A store built by migrations 0001..0040 holding the paper study's answers (a single entry, a double entry with
    a resolved discrepancy, a link, a draft) opens with every answer as it was, keyed by the study's single
    questionnaire phase `survey`; its final answers and export are those a store without occasions gives."""
    from study.folder.definition import load
    from study.store.studies import _item_rows
    from study.survey.answers import final_responses

    old = tmp_path / "old"
    old.mkdir()
    for m in migrate.discover():
        if m.version <= 40:
            shutil.copy(m.path, old)
    study = load(Path(__file__).parents[2] / "studies" / "pedas_paper")
    ins = study.instrument()
    con = duckdb.connect(str(tmp_db))
    migrate.migrate(con, old)
    con.execute("INSERT INTO study_definitions VALUES (1, 'pedas_paper', 't', ?, ?, NULL, now()::timestamp, 'x')",
                [study.hash, json.dumps(study.files, sort_keys=True)])
    con.execute("INSERT INTO instruments VALUES (?, '1', ?, now()::timestamp)", [ins.name, len(ins.items)])
    for row in _item_rows(ins):
        con.execute(f"INSERT INTO items ({', '.join(row)}) VALUES ({', '.join('?' for _ in row)})", list(row.values()))
    con.execute("INSERT INTO participants VALUES ('P001', 'paper_v1', 1, now()::timestamp), "
                "('P002', 'paper_v1', 1, now()::timestamp), ('P003', 'paper_v1', 1, now()::timestamp)")
    scaled = [i for i in ins.items.index if ins.items.loc[i, "response_type"] != "text"
              and i not in ("AGE", "GENDER", "LICENSE_YEARS", "STYLE", "ECO_FAM")]
    for k, item in enumerate(scaled):
        con.execute("INSERT INTO responses VALUES ('P001', ?, ?, 1, ?, NULL, 'participant', now()::timestamp)",
                    [ins.name, item, 1 + k % 5])
        for rnd in (1, 2):
            value = 5 if (item == "PU1" and rnd == 2) else 1 + (k + 1) % 5
            con.execute("INSERT INTO responses VALUES ('P002', ?, ?, ?, ?, NULL, 'ra', now()::timestamp)",
                        [ins.name, item, rnd, value])
    con.execute("INSERT INTO survey_submissions VALUES ('P001', ?, 1, 'web', false, 'participant', now()::timestamp),"
                " ('P002', ?, 1, 'entry', true, 'ra', now()::timestamp), "
                "('P002', ?, 2, 'entry', true, 'rb', now()::timestamp)", [ins.name] * 3)
    con.execute("INSERT INTO survey_resolutions VALUES ('P002', ?, 'PU1', 3, NULL, 'form says 3', 'rc', "
                "now()::timestamp)", [ins.name])
    con.execute("INSERT INTO survey_tokens VALUES (?, 'P003', ?, now()::timestamp, 'ra', NULL)", ["b" * 64, ins.name])
    con.execute("INSERT INTO survey_drafts VALUES ('P003', ?, 'PU1', 4, NULL, now()::timestamp)", [ins.name])
    before = {t: con.execute(f"SELECT * FROM {t} ORDER BY ALL").fetchall() for t in (
        "responses", "survey_submissions", "survey_resolutions", "survey_tokens", "survey_drafts")}
    con.close()

    with Store.open(tmp_db) as st:
        assert st.schema_version == migrate.code_version()
        for t, rows in before.items():
            cols = [c for c in st.columns(t) if c != "occasion"]
            after = st.con.execute(f"SELECT {', '.join(cols)} FROM {t} ORDER BY ALL").fetchall()
            assert after == rows, t
            assert st.one(f"SELECT list(DISTINCT occasion) FROM {t}") == ["survey"], t
        final = final_responses(st).set_index("participant_id")
        assert list(final.index) == ["P001", "P002"]
        assert final.loc["P002", "PU1"] == 3.0        # the resolution wins, as before
        assert final.loc["P001", scaled].tolist() == [float(1 + k % 5) for k in range(len(scaled))]

