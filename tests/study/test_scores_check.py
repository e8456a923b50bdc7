"""`study check` on study folders with broken score declarations or includes: one line per problem, naming file,
line and field; exit 2. And a study that includes shipped instruments is stored with their texts and scored from
the store."""
from __future__ import annotations

from pathlib import Path

import pytest

from pedas_study.cli.study import template_files

GOOD_SCORE = '\n[[scores]]\nname = "usefulness"\nitems = ["PU1", "PU2", "PU3"]\naggregate = "mean"\n'


def folder(tmp_path: Path, extra: str = "", include: str | None = None) -> Path:
    """The `study new` template (instrument acceptance_v1: PU1-3, EOU1-3 with EOU3 reversed, BI1-3, text COMMENT)
    with `extra` appended to study.toml and an optional `include = ...` line in its [instrument] table."""
    d = tmp_path / "st"
    d.mkdir()
    for name, text in template_files("st", str(d)).items():
        if name == "study.toml":
            if include is not None:
                text = text.replace("[instrument]\n", f"[instrument]\ninclude = {include}\n", 1)
            text += extra
        (d / name).write_text(text, encoding="utf-8")
    return d


def check(cli, d: Path) -> list[str]:
    r = cli("study", "check", d, db=None)
    lines = [ln.replace(f"{d}/", "") for ln in r.out.splitlines()]
    assert (r.code == 2) == bool(lines and "OK" not in lines[0]), (r.code, r.out, r.err)
    return lines


def line(d: Path, text: str) -> int:
    """1-based line of the first line of study.toml starting with `text`."""
    return next(k for k, ln in enumerate((d / "study.toml").read_text().splitlines(), 1) if ln.startswith(text))


def test_good_declarations_and_includes_pass(cli, tmp_path):
    d = folder(tmp_path, GOOD_SCORE, include='["sus", "nasa_tlx_raw", "ssq"]')
    out = check(cli, d)
    assert len(out) == 1 and out[0].startswith("study st OK:")
    assert "instrument sus_v1 (10 items)" in out[0] and "instrument ssq_v1 (16 items)" in out[0]


@pytest.mark.parametrize("extra, include, want", [
    # unknown item, and an item that is not scaled
    ('\n[[scores]]\nname = "u"\nitems = ["PU1", "PU9", "COMMENT"]\naggregate = "mean"\n', None,
     ["study.toml:{items}: scores.u.items: 'PU9' is not an item of instrument acceptance_v1",
      "study.toml:{items}: scores.u.items: 'COMMENT' is a text item; a score takes scaled items (likert, semantic, "
      "slider)"]),
    # reversed item not in the score
    ('\n[[scores]]\nname = "u"\nitems = ["PU1", "PU2"]\nreversed = ["EOU3"]\naggregate = "sum"\n', None,
     ["study.toml:{reversed}: scores.u.reversed: reversed item 'EOU3' is not among the score's items"]),
    # weights count mismatch
    ('\n[[scores]]\nname = "u"\nitems = ["PU1", "PU2"]\nweights = [1, 2, 3]\naggregate = "sum"\n', None,
     ["study.toml:{weights}: scores.u.weights: 3 weights for 2 items"]),
    # transform not numeric, aggregate unknown
    ('\n[[scores]]\nname = "u"\nitems = ["PU1"]\naggregate = "median"\nmultiply = "2.5"\n', None,
     ["study.toml:{aggregate}: scores.u.aggregate: 'median' is not sum | mean",
      "study.toml:{multiply}: scores.u.multiply: '2.5' is not a number"]),
    # duplicate score names, also against an included instrument's score
    (GOOD_SCORE + GOOD_SCORE.replace("usefulness", "sus"), '["sus"]',
     ["study.toml:{name}: scores.sus.name: score 'sus' declared twice (also in studies/instruments/sus.toml)"]),
    # an include that is not shipped, one twice
    ("", '["sus", "sus_scale", "sus"]',
     ["study.toml:{include}: instrument.include: 'sus_scale' is not a shipped instrument (jian_trust, nasa_tlx_raw, "
      "nasa_tlx_weighted, ssq, sus, van_der_laan)",
      "study.toml:{include}: instrument.include: 'sus' included twice"]),
    # a score of an instrument the study does not have, an unknown key
    ('\n[[scores]]\nname = "u"\ninstrument = "tlx"\nitems = ["PU1"]\naggregate = "sum"\n'
     '\n[[scores]]\nname = "v"\nitems = ["PU1"]\naggregate = "sum"\nscale = 2\n', None,
     ["study.toml:{instrument}: scores.u.instrument: 'tlx' is not an instrument of the study (acceptance_v1)",
      "study.toml:{scale}: scores[1].scale: unknown key (known: name, label, instrument, items, reversed, weights, "
      "weights_from, weights_total, aggregate, multiply, add)"]),
    # weights from items that do not exist, and a total without them
    ('\n[[scores]]\nname = "u"\nitems = ["PU1", "PU2"]\nweights_from = ["W1", "W2"]\naggregate = "mean"\n'
     '\n[[scores]]\nname = "v"\nitems = ["PU1"]\nweights_total = 15\naggregate = "mean"\n', None,
     ["study.toml:{weights_from}: scores.u.weights_from: 'W1' is not an item of instrument acceptance_v1",
      "study.toml:{weights_from}: scores.u.weights_from: 'W2' is not an item of instrument acceptance_v1",
      "study.toml:{weights_total}: scores.v.weights_total: a number, with weights_from (the total each "
      "participant's weights must reach)"]),
])
def test_broken_folders_name_every_problem(cli, tmp_path, extra, include, want):
    d = folder(tmp_path, extra, include)
    lines = (d / "study.toml").read_text().splitlines()

    def last(key: str) -> int:            # the last line of study.toml that sets `key` (the broken table's)
        return max(k for k, ln in enumerate(lines, 1) if ln.startswith(f"{key} ="))
    got = check(cli, d)
    keys = {k: last(k) for k in ("items", "reversed", "weights", "aggregate", "multiply", "name", "include",
                                 "instrument", "scale", "weights_from", "weights_total")
            if any(ln.startswith(f"{k} =") for ln in lines)}
    assert got == [w.format(**keys) for w in want]


def test_included_instruments_are_stored_with_the_study_and_scored_from_the_store(cli, tmp_path):
    import json

    from analysis.survey.scores import instrument_scores
    from study.store.store import Store
    from study.store.studies import definition

    d = folder(tmp_path, include='["sus"]')
    proto = json.loads((d / "protocol.json").read_text())
    proto["phases"][-1]["instrument"] = "acceptance"       # with occasions, every instrument has its phase
    proto["phases"].append({"name": "usability", "planned_minutes": 5, "drive": False, "condition": None,
                            "instrument": "sus"})
    for order in proto.get("orders", {}).values():      # every order lists each phase once
        order.append("usability")
    (d / "protocol.json").write_text(json.dumps(proto))
    db = tmp_path / "s.duckdb"
    assert cli("init", "--study", d, db=db).code == 0
    assert cli("participant", "add", "P001", "--attr", "age=30", "--attr", "gender=female", "--attr",
               "license_years=5", db=db).code == 0
    f = tmp_path / "sus.csv"
    f.write_text("participant_id," + ",".join(f"SUS{k}" for k in range(1, 11)) + "\nP001,5,4,2,1,2,3,2,4,5,2\n")
    r = cli("survey", "import", f, "--instrument", "sus_v1", db=db)
    assert r.code == 0, r.err
    st = Store.open(db)
    try:
        stored = json.loads(st.df("SELECT files FROM study_definitions")["files"].item())
        assert "studies/instruments/sus.csv" in stored and "studies/instruments/sus.toml" in stored
        assert "sus_v1" in definition(st).instruments
        out = instrument_scores(st, "sus")
    finally:
        st.close()
    assert out[["participant_id", "score", "value"]].values.tolist() == [["P001", "sus", 55.0]]
