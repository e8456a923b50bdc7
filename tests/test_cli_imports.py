"""What the command line imports: building the parser (``--help``) loads none of the numeric and statistics
libraries, and listing participants loads no model, statistics, units or plotting library. A fact about
``sys.modules`` in a fresh process, not a timing (how fast it starts is measured by running the commands, see
docs/architecture.md)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

from tests.conftest import LK_STUDY, REPO

HELP_FORBIDDEN = ("pandas", "numpy", "scipy", "semopy", "statsmodels", "sympy", "pint", "matplotlib")
# a listing returns a DataFrame (pandas, hence numpy) from the store (duckdb); nothing else heavy
LIST_FORBIDDEN = ("semopy", "statsmodels", "sympy", "scipy", "pint", "matplotlib")

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
from study.store import Store
from study.studies import definition
with Store.open({str(lk_db)!r}, read_only=True) as st:
    study = definition(st)
    read = "semopy" in sys.modules
    m = study.model
print(json.dumps({{"semopy_on_read": read, "semopy_on_use": "semopy" in sys.modules,
                  "model": [m.measurement, [[r.name, r.dv, r.steps] for r in m.regressions],
                            [list(vars(h).values()) for h in m.hypotheses]]}}))
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=REPO, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(p.stdout)
    assert r["semopy_on_read"] is False and r["semopy_on_use"] is True

    from study.definition import load

    m = load(LK_STUDY).model
    want = [{c: list(v) for c, v in m.measurement.items()}, [[x.name, x.dv, [list(s) for s in x.steps]]
                                                            for x in m.regressions],
            [list(vars(h).values()) for h in m.hypotheses]]
    assert r["model"] == want and m.hypotheses  # the example study's model has hypotheses to compare
