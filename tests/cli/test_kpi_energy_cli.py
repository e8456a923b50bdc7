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


def test_source_is_named_and_a_power_column_is_measured(cli, tmp_path, trace_csv):
    path, t, v = trace_csv
    r = cli("kpi", "energy", "--trace", path, "--json")
    assert json.loads(r.out)["energy_source"] == "modelled (Nissan Leaf parameters)"
    # the same trace with a logged battery power of 7.2 kW for 119.5 s: 239 Wh, whatever the model says
    measured = tmp_path / "measured.csv"
    pd.DataFrame({"t": t, "v": v, "grade": 0.01, "p_batt": 7200.0}).to_csv(measured, index=False)
    r = cli("kpi", "energy", "--trace", measured, "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["energy_source"] == "measured (p_batt column)"
    assert out["energy_wh"] == pytest.approx(7200.0 * (t[-1] - t[0]) / 3600.0, abs=0.01)
    r = cli("kpi", "energy", "--trace", measured)
    assert "source       measured (p_batt column)" in r.out and "239.0 Wh" in r.out


def test_no_power_and_no_model_is_unavailable_not_a_substitute(cli, trace_csv):
    path, _, _ = trace_csv
    r = cli("kpi", "energy", "--trace", path, "--model", "none", "--json")
    assert r.code == 0, r.err
    out = json.loads(r.out)
    assert out["energy_wh"] is None and out["wh_per_km"] is None and out["energy_source"] == "unavailable"
    assert "no p_batt column" in out["note"]
    r = cli("kpi", "energy", "--trace", path, "--model", "none")
    assert "energy       n/a" in r.out and "energy unavailable" in r.out


def test_bad_power_value_is_one_line_error(cli, tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("t,v,p_batt\n0,1,100\n1,2,abc\n")
    r = cli("kpi", "energy", "--trace", path)
    assert r.code == 2 and "line 3: p_batt must be a number" in r.err and len(r.err.strip().splitlines()) == 1
