"""`pedas-study kpi energy --trace CSV` end to end."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pedas.power import trace_energy


@pytest.fixture
def trace_csv(tmp_path):
    t = np.arange(0.0, 120.0, 0.5)
    v = np.clip(t * 0.8, 0.0, 15.0)
    path = tmp_path / "trace.csv"
    pd.DataFrame({"t": t, "v": v, "grade": 0.01}).to_csv(path, index=False)
    return path, t, v


def test_table_output(cli, trace_csv):
    path, t, v = trace_csv
    r = cli("kpi", "energy", "--trace", path)
    assert r.code == 0, r.err
    expected = trace_energy(t, v, np.full_like(t, 0.01))
    assert f"{expected.wh:.1f} Wh" in r.out
    assert f"{expected.wh_per_km:.1f} Wh/km" in r.out


def test_json_output(cli, trace_csv):
    path, t, v = trace_csv
    r = cli("kpi", "energy", "--trace", path, "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    expected = trace_energy(t, v, np.full_like(t, 0.01))
    assert out["energy_wh"] == pytest.approx(expected.wh, abs=0.01)
    assert out["wh_per_km"] == pytest.approx(expected.wh_per_km, abs=0.01)
    assert out["samples"] == t.size


def test_grade_is_optional(cli, tmp_path):
    path = tmp_path / "flat.csv"
    path.write_text("t,v\n0,10\n1,10\n2,10\n")
    r = cli("kpi", "energy", "--trace", path, "--json")
    assert r.code == 0 and json.loads(r.out)["distance_km"] == pytest.approx(0.02)


@pytest.mark.parametrize("content,needle", [
    ("time,speed\n0,1\n1,2\n", "missing column"),
    ("t,v\n0,1\n1,abc\n", "line 3"),
    ("t,v\n0,1\n0,2\n", "increasing"),
    ("t,v\n0,1\n1,-5\n", ">= 0"),
    ("", "not a readable CSV"),
])
def test_bad_trace_is_one_line_error(cli, tmp_path, content, needle):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    r = cli("kpi", "energy", "--trace", path)
    assert r.code == 2
    assert r.out == ""
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pedas-study: error:") and needle in lines[0], r.err


def test_missing_file_as_a_process(cli_proc, tmp_path):
    r = cli_proc("kpi", "energy", "--trace", tmp_path / "nope.csv")
    assert r.code == 2
    assert r.err.strip().count("\n") == 0 and "not found" in r.err
