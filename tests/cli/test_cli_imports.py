"""What the command line imports: building the parser (``--help``) loads none of the numeric and statistics
libraries, and the everyday commands (``participant list`` in every format, ``participant add``, ``session
advance``, ``participant import``) load none of them either: they read and write the store through DuckDB alone.
A fact about ``sys.modules`` in a fresh process, not a timing (how fast it starts is measured by running the
commands, `pedas-study bench cli`, see docs/architecture.md)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from pedas_study.cli.common import LIST_FORMATS
from tests.conftest import LK_STUDY, REPO

HELP_FORBIDDEN = ("pandas", "numpy", "scipy", "semopy", "statsmodels", "sympy", "pint", "matplotlib")
# no model, statistics, units or plotting library for a listing (the first guard, kept)
LIST_FORBIDDEN = ("semopy", "statsmodels", "sympy", "scipy", "pint", "matplotlib")
# the everyday commands: rows from DuckDB, no DataFrame (pandas, with numpy and pyarrow behind it)
EVERYDAY_FORBIDDEN = HELP_FORBIDDEN + ("pyarrow",)

# runs main(argv) in a fresh interpreter; prints the top-level packages loaded before and after, and its exit code
PROBE = """
import contextlib, io, json, sys
before = sorted({m.split(".")[0] for m in sys.modules})
from pedas_study.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        code = main(json.loads(sys.argv[1]))
    except SystemExit as exc:
        code = exc.code
after = sorted({m.split(".")[0] for m in sys.modules})
print(json.dumps({"code": code, "out": out.getvalue(), "before": before, "after": after}))
"""


def _probe(*argv: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-c", PROBE, json.dumps(list(argv))], capture_output=True, text=True,
                       env=env, cwd=REPO, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])
    print(f"\n$ pedas-study {' '.join(argv)}\n  loaded at start ({len(r['before'])}): {' '.join(r['before'])}\n"
          f"  loaded by the command ({len(set(r['after']) - set(r['before']))}): "
          f"{' '.join(sorted(set(r['after']) - set(r['before'])))}")
    return r


def test_help_imports_no_numeric_or_statistics_library():
    r = _probe("--help")
    assert r["code"] == 0
    assert r["out"].startswith("usage: pedas-study") and "participant" in r["out"] and "analyze" in r["out"]
    assert [m for m in HELP_FORBIDDEN if m in r["after"]] == []


def test_a_subcommand_help_too():
    r = _probe("session", "schedule", "--help")
    assert r["code"] == 0 and "--buffer" in r["out"] and "default 15" in r["out"]
    assert [m for m in HELP_FORBIDDEN if m in r["after"]] == []


def test_participant_list_loads_no_model_statistics_or_units_library(lk_db, cli):
    assert cli("participant", "add", "LK-01", "--attr", "age=30").code == 0
    r = _probe(f"--db={lk_db}", "participant", "list", "--format", "csv")
    assert r["code"] == 0
    assert r["out"].splitlines()[1].startswith("LK-01,")
    assert [m for m in LIST_FORBIDDEN if m in r["after"]] == []
    assert "duckdb" in r["after"]  # the store was read, not skipped


def test_the_stored_model_is_parsed_on_use_and_equals_the_checked_one(lk_db):
    """Reading the stored study loads no model parser; its model, parsed when first used, is the one the check
    parsed from the folder."""
    code = f"""
import json, sys
from study.store.store import Store
from study.store.studies import definition
with Store.open({str(lk_db)!r}, read_only=True) as st:
    study = definition(st)
    read = "semopy" in sys.modules or "study._semopy_parser" in sys.modules
    m = study.model
print(json.dumps({{"semopy_on_read": read, "semopy_on_use": "semopy" in sys.modules,
                  "parser_on_use": "study._semopy_parser" in sys.modules,
                  "model": [m.measurement, [[r.name, r.dv, r.steps] for r in m.regressions],
                            [list(vars(h).values()) for h in m.hypotheses]]}}))
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(p.stdout)
    # parsed on use by semopy's parser file alone (study.folder.lavaan_parser), not by the semopy package
    assert r["semopy_on_read"] is False and (r["semopy_on_use"], r["parser_on_use"]) == (False, True)

    from study.folder.definition import load

    m = load(LK_STUDY).model
    want = [{c: list(v) for c, v in m.measurement.items()}, [[x.name, x.dv, [list(s) for s in x.steps]]
                                                            for x in m.regressions],
            [list(vars(h).values()) for h in m.hypotheses]]
    assert r["model"] == want and m.hypotheses  # the example study's model has hypotheses to compare


def _heavy(r: dict) -> list[str]:
    return [m for m in EVERYDAY_FORBIDDEN if m in r["after"]]


@pytest.mark.parametrize("fmt", LIST_FORMATS)
def test_participant_list_loads_no_pandas_in_any_format(lk_db, cli, fmt):
    """Every format of the listing, with missing values and a float attribute, printed as the DataFrame listing
    prints it (format_frame of list_participants)."""
    from pedas_study.cli.common import format_frame
    from study.people.participants import list_participants
    from study.store.store import Store

    assert cli("participant", "add", "LK-01", "--attr", "age=30").code == 0
    assert cli("participant", "add", "LK-02", "--attr", "age=41", "--attr", "gender=male",
               "--attr", "km_per_year=1000.5").code == 0
    r = _probe(f"--db={lk_db}", "participant", "list", "--format", fmt)
    assert r["code"] == 0 and _heavy(r) == [] and "duckdb" in r["after"]
    with Store.open(lk_db, read_only=True) as st:
        assert r["out"] == format_frame(list_participants(st), fmt) + "\n"


def test_participant_add_loads_no_pandas(paper_db):
    """The paper's study: attributes typed and range-checked, its [[checks]] evaluated, the row stored."""
    from study.store.store import Store

    r = _probe(f"--db={paper_db}", "participant", "add", "P001", "--attr", "age=30", "--attr", "gender=female",
               "--attr", "license_years=5", "--attr", "style=normal", "--attr", "eco_familiarity=3")
    assert (r["code"], r["out"]) == (0, "participant P001 added (protocol paper_v1)\n")
    assert _heavy(r) == [] and "duckdb" in r["after"]
    with Store.open(paper_db, read_only=True) as st:
        assert st.one("SELECT value FROM participant_attributes WHERE attribute = 'license_years'") == "5"
    refused = _probe(f"--db={paper_db}", "participant", "add", "P002", "--attr", "age=20",
                     "--attr", "license_years=9")     # the study's check: a licence from 16 on
    assert refused["code"] == 2 and _heavy(refused) == []


def test_session_advance_loads_no_pandas(paper_db, cli, tmp_path):
    assert cli("participant", "add", "P001", "--attr", "age=30").code == 0
    assert cli("participant", "add", "P002", "--attr", "age=31").code == 0
    r = _probe(f"--db={paper_db}", "session", "advance", "P001", "familiarisation")
    assert (r["code"], r["out"]) == (0, "P001: familiarisation started\n")
    assert _heavy(r) == [] and "duckdb" in r["after"]
    r = _probe(f"--db={paper_db}", "session", "advance", "P001", "baseline_drive")
    assert (r["code"], r["out"]) == (0, "P001: baseline_drive started (familiarisation completed)\n")
    assert _heavy(r) == []
    events = tmp_path / "events.csv"
    events.write_text("participant_id,phase\nP002,familiarisation\nP002,baseline_drive\n", encoding="utf-8")
    r = _probe(f"--db={paper_db}", "session", "advance", "--from", str(events))
    assert (r["code"], r["out"]) == (0, f"applied 2 events for 1 participants from {events}\n")
    assert _heavy(r) == []


def test_participant_import_loads_no_pandas(paper_db, tmp_path):
    """A small roster read with the csv module, each row through the registration checks, all stored; a roster
    with a bad row is refused, naming it, without pandas too."""
    from study.store.store import Store

    roster = tmp_path / "roster.csv"
    roster.write_text("participant_id,age,gender,license_years,style,eco_familiarity\n"
                      "P001,30,female,5,normal,3\nP002,41,male,,sporty,\nP003,22,,4,,1\n", encoding="utf-8")
    r = _probe(f"--db={paper_db}", "participant", "import", str(roster))
    assert (r["code"], r["out"]) == (0, f"registered 3 participants from {roster}\n")
    assert _heavy(r) == [] and "duckdb" in r["after"]
    with Store.open(paper_db, read_only=True) as st:
        assert st.one("SELECT count(*) FROM participants") == 3
    bad = tmp_path / "bad.csv"
    bad.write_text("participant_id,age,license_years\nP004,20,9\n", encoding="utf-8")
    r = _probe(f"--db={paper_db}", "participant", "import", str(bad))
    assert r["code"] == 2 and _heavy(r) == []


def test_session_advance_assigning_an_order_loads_no_pandas(lk_db, cli):
    """The lane-keeping protocol has two condition orders: the first advance assigns the balanced one."""
    from study.store.store import Store

    for pid in ("LK-01", "LK-02"):
        assert cli("participant", "add", pid, "--attr", "age=30").code == 0
        r = _probe(f"--db={lk_db}", "session", "advance", pid, "familiarisation")
        assert (r["code"], r["out"]) == (0, f"{pid}: familiarisation started\n")
        assert _heavy(r) == []
    with Store.open(lk_db, read_only=True) as st:
        assert st.con.execute("SELECT participant_id, order_name FROM order_assignments ORDER BY 1").fetchall() \
            == [("LK-01", "hud_first"), ("LK-02", "no_hud_first")]


# ------------------------------------------------------------------ analysis commands on a study folder
ANSWERS = REPO / "data" / "reference" / "survey.csv"
PAPER = REPO / "studies" / "pedas_paper"


def test_plan_power_loads_neither_pint_nor_semopy(tmp_path):
    """`plan power` reads no drive log and fits nothing: the study folder is checked without the unit checks
    (no pint) and its model file is read by semopy's parser file alone (no semopy, sympy or scikit-learn)."""
    out = tmp_path / "power"
    r = _probe(f"--db={tmp_path / 'none.duckdb'}", "plan", "power", "--responses", str(ANSWERS), "--study",
               str(PAPER), "--out", str(out))
    assert r["code"] == 0 and r["out"].startswith("power of 7 hypotheses") and (out / "power.csv").is_file()
    assert [m for m in ("pint", "dask", "semopy", "sympy", "sklearn") if m in r["after"]] == []


@pytest.mark.parametrize("command", ["survey", "extended"])
def test_analyze_on_a_study_folder_loads_no_pint(tmp_path, command):
    """`analyze survey|extended --study DIR` reads no drive log: no unit registry (semopy is loaded: it fits)."""
    r = _probe(f"--db={tmp_path / 'none.duckdb'}", "analyze", command, "--responses", str(ANSWERS), "--study",
               str(PAPER), "--bootstrap", "0", "--out", str(tmp_path / command))
    assert r["code"] == 0 and "semopy" in r["after"]
    assert [m for m in ("pint", "dask") if m in r["after"]] == []
