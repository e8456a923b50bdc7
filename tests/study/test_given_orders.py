"""Orders as they happened: `session assign ID --order NAME --reason`, a roster's `order` column, the balance report
of `session orders` with its deviations from the balanced draw, and the order and current phase in `session status`
and `participant list` (the lane-keeping study: orders hud_first, no_hud_first)."""
from __future__ import annotations

import json

from study.store.store import Store


def _audit(db) -> list[dict]:
    with Store.open(db, read_only=True) as st:
        return [json.loads(n) for n in st.df("SELECT new FROM audit_log WHERE table_name = 'order_assignments' "
                                             "ORDER BY audit_id")["new"]]


def test_a_roster_and_assign_record_given_orders_and_the_balance_report_names_each_deviation(lk_db, cli, tmp_path):
    roster = tmp_path / "roster.csv"
    roster.write_text("participant_id,age,order\nLK-01,30,no_hud_first\nLK-02,31,no_hud_first\nLK-03,32,\n",
                      encoding="utf-8")
    r = cli("participant", "import", roster, db=lk_db)
    assert r.code == 0 and r.out.strip() == f"registered 3 participants from {roster}", r.err
    assert cli("session", "assign", "LK-03", db=lk_db).out.strip() == "LK-03: order hud_first"   # the draw
    assert cli("participant", "add", "LK-04", "--attr", "age=40", db=lk_db).code == 0
    r = cli("session", "assign", "LK-04", "--order", "no_hud_first", "--reason", "HUD unit away for repair",
            db=lk_db)
    assert r.code == 0 and r.out.strip() == "LK-04: order no_hud_first (given)"
    # LK-01's given order is the draw; LK-02's and LK-04's are not
    rows = _audit(lk_db)
    assert [(a["participant_id"], a["order_name"], a["drawn"], a["given"], a["reason"]) for a in rows] == [
        ("LK-01", "no_hud_first", "hud_first", True, f"roster {roster}"),
        ("LK-02", "no_hud_first", "hud_first", True, f"roster {roster}"),
        ("LK-03", "hud_first", "hud_first", False, None),
        ("LK-04", "no_hud_first", "hud_first", True, "HUD unit away for repair")]
    r = cli("session", "orders", db=lk_db)
    assert r.code == 0
    lines = r.out.splitlines()
    assert lines[1].split() == ["lk_counterbalanced_v1", "hud_first", "1", "0", "0", "1"]
    assert lines[2].split() == ["lk_counterbalanced_v1", "no_hud_first", "3", "3", "0", "3"]
    assert lines[3:] == [
        "lk_counterbalanced_v1: active participants per order differ by 2 (the design keeps them within 1)",
        f"deviation: LK-01 drove no_hud_first, the balanced draw was hud_first: roster {roster}",
        f"deviation: LK-02 drove no_hud_first, the balanced draw was hud_first: roster {roster}",
        "deviation: LK-04 drove no_hud_first, the balanced draw was hud_first: HUD unit away for repair"]
    report = json.loads(cli("session", "orders", "--format", "json", db=lk_db).out)
    assert [d["participant_id"] for d in report["deviations"]] == ["LK-01", "LK-02", "LK-04"]

    assert cli("session", "advance", "LK-04", "familiarisation", db=lk_db).code == 0
    r = cli("session", "status", "LK-04", db=lk_db)
    assert r.out.splitlines()[:2] == ["LK-04 (protocol lk_counterbalanced_v1, order no_hud_first (given: HUD unit "
                                      "away for repair))", "current phase: familiarisation (in progress)"]
    listing = json.loads(cli("participant", "list", "--format", "json", db=lk_db).out)
    assert [(p["participant_id"], p["order"], p["phase"]) for p in listing] == [
        ("LK-01", "no_hud_first", None), ("LK-02", "no_hud_first", None), ("LK-03", "hud_first", None),
        ("LK-04", "no_hud_first", "familiarisation")]


def test_a_given_order_is_refused_when_unknown_or_once_the_protocol_has_started(lk_db, cli, tmp_path):
    assert cli("participant", "add", "LK-01", "--attr", "age=30", db=lk_db).code == 0
    r = cli("session", "assign", "LK-01", "--order", "hud_last", db=lk_db)
    assert r.code == 2 and r.err.strip() == ("pedas-study: error: protocol lk_counterbalanced_v1 has no order "
                                             "'hud_last' (orders: hud_first, no_hud_first)")
    assert cli("session", "assign", "LK-01", "--reason", "x", db=lk_db).code == 2   # --reason without --order
    assert cli("session", "assign", "LK-01", db=lk_db).out.strip() == "LK-01: order hud_first"
    # before the first phase a given order replaces the draw (audited as an update) ...
    assert cli("session", "assign", "LK-01", "--order", "no_hud_first", "--reason", "swapped", db=lk_db).code == 0
    assert _audit(lk_db)[-1] == {"given": True, "order_name": "no_hud_first", "reason": "swapped"}
    assert cli("session", "advance", "LK-01", "familiarisation", db=lk_db).code == 0
    # ... afterwards the order the participant drives cannot change
    r = cli("session", "assign", "LK-01", "--order", "hud_first", db=lk_db)
    assert r.code == 2 and r.err.strip() == ("pedas-study: error: LK-01 has order no_hud_first and has started the "
                                             "protocol (familiarisation); the order cannot change")
    roster = tmp_path / "roster.csv"
    roster.write_text("participant_id,age,order\nLK-02,30,sideways\n", encoding="utf-8")
    r = cli("participant", "import", roster, db=lk_db)
    assert r.code == 2 and "line 2: LK-02: protocol lk_counterbalanced_v1 has no order 'sideways'" in r.err
