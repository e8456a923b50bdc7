"""The researcher console over HTTP (Flask's test client on a real store): each action refused with the study
function's one-line message and the store unchanged; the upload answers an XHR with JSON and refuses bodies over
its limit; the console and the CLI give the same completeness table; `survey revoke` and `participant completeness`
through the CLI with hand-worked expectations."""
from __future__ import annotations

import html as html_text
import io
import json
import re
import zipfile

import pytest

from study.survey import answers as sv
from study.survey.completeness import completeness
from study.people.exclusions import exclude
from study.people.participants import add_participant
from study.people.protocol import advance, complete
from study.store.store import Store
from study.webapp import console
from tests.study.test_drive_import import make_drive
from tests.study.test_survey_web import seeded_answers

PHASES = ["familiarisation", "baseline_drive", "pedas_intro", "practice", "pedas_drive", "survey"]


@pytest.fixture
def store(console_store):
    return console_store


@pytest.fixture
def client(console_client):
    return console_client


def flashed(client) -> list[str]:
    """The messages the next page shows."""
    html = client.get("/r/today").get_data(as_text=True)
    return [html_text.unescape(m.strip()) for m in re.findall(r'<p class="flash [a-z]+" role="\w+">([^<]*)</p>', html)]


def snapshot(st):
    return st.counts(), st.df("SELECT * FROM audit_log ORDER BY audit_id").to_json(date_format="iso")


REFUSED = [  # (path, form, the one-line message shown)
    ("/r/participants", {"participant_id": "X1"}, "participant id 'X1'"),
    ("/r/participants", {"participant_id": "P003", "age": "7"}, "age"),
    ("/r/participants", {"participant_id": "P001"}, "participant P001 already exists"),
    ("/r/p/P001/start", {"phase": "survey"},
     "phase out of order: P001 is at the start, next is familiarisation, not survey"),
    ("/r/p/P001/start", {"phase": "nap"}, "unknown phase 'nap'"),
    ("/r/p/P001/end", {}, "P001 has no phase in progress to complete"),
    ("/r/p/P001/abort", {"reason": " "}, "an abort needs a reason"),
    ("/r/p/P001/exclude", {"scope": "some", "reason": "other"}, "scope"),
    ("/r/p/P001/exclude/revoke", {"scope": "all"}, "P001 has no exclusion with scope all"),
    ("/r/p/P001/link/revoke", {}, "P001 has no active survey link"),
    ("/r/p/P009/start", {"phase": "familiarisation"}, "P009"),
    ("/r/p/P001/drive", {}, "choose a drive-log file to upload"),
    ("/r/book", {"participant_id": "P001", "at": "2020-01-06T09:00"},
     "2020-01-06 09:00 is in the past; book a future slot"),
    ("/r/book", {"participant_id": "P001", "at": "tomorrow"}, "tomorrow"),
    ("/r/appointment", {"participant_id": "P001", "status": "booked"}, "unknown appointment status 'booked'"),
]


@pytest.mark.parametrize("path, form, text", REFUSED, ids=[f"{p} {t[:30]}" for p, _, t in REFUSED])
def test_a_refused_action_shows_one_line_and_changes_nothing(store, client, path, form, text):
    before = snapshot(store)
    r = client.post(path, data={**form, "csrf": client.csrf})
    assert r.status_code == 303
    shown = flashed(client)
    assert len(shown) == 1 and text in shown[0] and "\n" not in shown[0], shown
    assert snapshot(store) == before


def test_excluded_participant_cannot_advance(store, client):
    exclude(store, "P001", "all", "withdrawn")
    before = snapshot(store)
    client.post("/r/p/P001/start", data={"phase": "familiarisation", "csrf": client.csrf})
    assert flashed(client) == ["P001 is excluded from all analyses (withdrawn); the protocol is closed"]
    assert snapshot(store) == before
    assert "protocol closed" in client.get("/r/p/P001").get_data(as_text=True)


def test_upload_over_xhr_gets_json_and_imports_as_the_cli_does(store, client, tmp_path):
    buf = io.BytesIO()
    make_drive(500).to_csv(buf, index=False)
    r = client.post("/r/p/P001/drive", headers={"X-Requested-With": "XMLHttpRequest"},
                    data={"csrf": client.csrf, "condition": "baseline",
                          "file": (io.BytesIO(buf.getvalue()), "../../P001 baseline.csv")},
                    content_type="multipart/form-data")
    assert r.status_code == 200 and r.get_json() == {"next": "/r/p/P001", "ok": True}
    assert re.match(r"P001 baseline: imported drive \d+, 500 samples", flashed(client)[0])
    row = store.df("SELECT n_samples, file_name, source FROM drives").iloc[0].tolist()
    assert row == [500, "P001 baseline.csv", "import"]                 # the client's name, without its folder
    r = client.post("/r/p/P001/drive", data={"csrf": client.csrf, "condition": "baseline",
                                            "file": (io.BytesIO(buf.getvalue()), "P001_baseline.csv")},
                    content_type="multipart/form-data")
    assert r.status_code == 303 and "unchanged" in flashed(client)[0]   # the same log again: a no-op


def test_upload_over_the_limit_is_refused(store, client, monkeypatch):
    monkeypatch.setattr(console, "DRIVE_UPLOAD_MAX", 4096)
    r = client.post("/r/p/P001/drive", data={"csrf": client.csrf, "condition": "baseline",
                                            "file": (io.BytesIO(b"t,s,v\n" * 2000), "big.csv")},
                    content_type="multipart/form-data")
    assert r.status_code == 413 and store.one("SELECT count(*) FROM drives") == 0


def test_export_download_is_the_export_of_the_cli(store, client, tmp_path):
    from study.export.writer import export

    r = client.post("/r/export", data={"csrf": client.csrf, "format": "csv"})
    assert r.status_code == 200 and r.headers["Content-Type"] == "application/zip"
    assert re.search(r'filename=pedas_paper-csv-\d{4}-\d{2}-\d{2}\.zip', r.headers["Content-Disposition"])
    export(store, "csv", tmp_path)
    with zipfile.ZipFile(io.BytesIO(r.data)) as z:
        for name in z.namelist():
            assert z.read(name) == (tmp_path / name).read_bytes(), name
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert sorted(z.namelist()) == sorted([*manifest["files"], "manifest.json"])
    r = client.post("/r/export", data={"csrf": client.csrf, "format": "xlsx"})
    assert r.status_code == 303 and "xlsx" in flashed(client)[0]


def test_calendar_is_the_cli_schedule_export(store, client, tmp_path):
    from study.people.scheduling import book, export_ics

    book(store, "P001", "2030-01-07T09:00", simulator="sim1")
    r = client.get("/r/calendar.ics")
    assert r.status_code == 200 and r.headers["Content-Type"].startswith("text/calendar")
    assert export_ics(store, tmp_path / "a.ics") == 1
    assert r.data == (tmp_path / "a.ics").read_bytes() and b"P001" in r.data


# ---------------------------------------------------------------------------------------------- completeness
def test_completeness_by_hand(store):
    """P001: every phase, both drives, survey submitted -> complete. P002: two phases, baseline drive only, no
    survey, excluded objective -> lacks the 4 phases and the survey, not the pedas drive. P003: nothing yet.
    P004: excluded all -> owes nothing."""
    from study.logs.importing import import_drive_frame

    for pid in ("P003", "P004"):
        add_participant(store, pid)
    for phase in PHASES:
        advance(store, "P001", phase)
    complete(store, "P001")
    for cond in ("baseline", "pedas"):
        import_drive_frame(store, "P001", cond, make_drive(200, seed=1 if cond == "baseline" else 2), source="import")
    sv.issue_link(store, "P001")
    sv.save_draft(store, "P001", seeded_answers(1))
    sv.submit_web(store, "P001")
    advance(store, "P002", "familiarisation")
    advance(store, "P002", "baseline_drive")
    complete(store, "P002")
    import_drive_frame(store, "P002", "baseline", make_drive(200, seed=3), source="import")
    exclude(store, "P002", "objective", "technical_issue")
    exclude(store, "P004", "all", "withdrawn")
    df = completeness(store).set_index("participant_id")
    assert df.loc["P001"].tolist() == ["paper_v1", "", 6, 6, "", "", "single", True]
    assert df.loc["P002"].tolist() == ["paper_v1", "objective", 2, 6, "pedas_intro, practice, pedas_drive, survey",
                                       "", "none", False]
    assert df.loc["P003"].tolist() == ["paper_v1", "", 0, 6, ", ".join(PHASES), "baseline, pedas", "none", False]
    assert df.loc["P004"].tolist() == ["paper_v1", "all", 0, 6, "", "", "none", True]


def test_cli_completeness_and_revoke(cli, paper_db):
    assert cli("participant", "add", "P001").code == 0
    r = cli("participant", "completeness", "--format", "json")
    assert r.code == 0 and json.loads(r.out) == [{
        "participant_id": "P001", "protocol": "paper_v1", "excluded": "", "phases_done": 0, "phases_total": 6,
        "missing_phases": ", ".join(PHASES), "missing_drives": "baseline, pedas", "survey": "none",
        "complete": False}]
    r = cli("survey", "revoke", "P001")
    assert r.code == 2 and r.err.strip() == "pedas-study: error: P001 has no active survey link"
    url = cli("survey", "link", "P001").out.strip()
    r = cli("survey", "revoke", "P001")
    assert r.code == 0 and r.out.strip() == "P001: 1 survey link revoked"
    with Store.open(paper_db, read_only=True) as st:
        with pytest.raises(sv.LinkError) as exc:
            sv.resolve_token(st, url.rsplit("/", 1)[1])
    assert exc.value.status == 403
    assert cli("survey", "revoke", "P009").code == 2
