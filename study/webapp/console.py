"""The researcher console (``/r/...``, behind the researcher sign-in): a study day in one place.

Each page calls the same `study` functions as the CLI command named next to it, through the app's store helper
(:func:`study.webapp.context.store`) with the signed-in researcher as the audit-log actor; a refused action shows
the function's one-line message and stores nothing. Every POST answers with a redirect (post/redirect/get) and a
flashed message, except the survey link (shown once, with its QR code) and the export (a download).

* ``today``: the day's appointments (`schedule day`), booking (`session schedule`), attended / no-show / cancel,
  the booked appointments as an .ics file (`schedule export`);
* ``participants``: the list (`participant list`) and registration with the study's attributes (`participant add`);
* ``p/<id>``: the protocol phases with start / end / abort buttons stamped with the server's clock (`session
  advance|complete|abort`), exclusions (`exclude`), drive-log upload (`drive import`), survey link issue / revoke
  (`survey link|revoke`), one row per questionnaire occasion (:mod:`study.webapp.occasion_rows`);
* ``completeness`` (`participant completeness`), ``export`` (`export`, as a ZIP download).
"""
from __future__ import annotations

import io
import re
import tempfile
import zipfile
from datetime import date, datetime, timedelta
from pathlib import Path

from flask import (
    Blueprint,
    flash,
    g,
    jsonify,
    redirect,
    render_template,
    request,
    send_file,
    url_for,
)
from werkzeug.utils import secure_filename

from study.common.errors import UserError
from study.common.times import when
from study.webapp.context import state, store
from study.webapp.researcher import actor, researcher

bp = Blueprint("console", __name__, url_prefix="/r")
DRIVE_UPLOAD_MAX = 512 * 1024 * 1024  # bytes of one uploaded drive log (a 2 h drive at 100 Hz is ~100 MB of CSV)
UPLOAD_NAME_MAX = 100  # characters of an uploaded file's name as saved (a file system allows 255 bytes)
FLASH_MAX = 300    # characters of a flashed message: it travels in the session cookie (browsers keep <= 4 kB)
REFILL_MAX = 200   # characters of a refused form's field shown again; a longer one comes back empty
_PID = re.compile(r"[A-Za-z0-9_.-]{1,64}")  # a participant id a redirect may carry (the store allows 1-64 chars)


@bp.before_request
def large_uploads():
    # only the drive-log upload takes large bodies; set before the sign-in check reads the form (and its CSRF token)
    if request.endpoint == "console.upload_drive":
        request.max_content_length = DRIVE_UPLOAD_MAX


def upload_name(filename: str) -> str:
    """An uploaded file's name as it is saved in a fresh temporary directory: only ASCII letters, digits, ``._-``
    (werkzeug's secure_filename: no directory part), at most UPLOAD_NAME_MAX characters keeping the extension (which
    gives the format); "" when nothing is left. The drive stores the client's name as sent
    (:func:`study.logs.importing.client_file_name`), which is never a path."""
    name = secure_filename(filename)
    if len(name) > UPLOAD_NAME_MAX:
        stem, dot, ext = name.rpartition(".")
        ext = dot + ext if stem and len(ext) <= 16 else ""
        name = name[:UPLOAD_NAME_MAX - len(ext)] + ext
    return name


def _records(df) -> list[dict]:
    """Rows of `df` as dicts with every missing value (NaN, NaT, NA) as None, for the templates."""
    return df.astype(object).where(df.notna(), None).to_dict("records")


def _short(text: str) -> str:
    """`text` on one line, at most FLASH_MAX characters (a message quoting a 70 kB field must not fill the cookie)."""
    text = " ".join(str(text).split())
    return text if len(text) <= FLASH_MAX else text[:FLASH_MAX - 1] + "…"


def _target(endpoint: str, values: dict) -> str:
    """The address a console redirect goes to. Request data reaches it only as a canonical day (``date``) or a
    plain participant id (``pid``); anything else is dropped (a bad pid goes to the participant list), so a
    redirect never echoes arbitrary request data into a Location header."""
    clean = {}
    day = values.get("date")
    if isinstance(day, str):
        try:
            clean["date"] = date.fromisoformat(day).isoformat()
        except ValueError:
            pass
    if "pid" in values:
        if not (isinstance(values["pid"], str) and _PID.fullmatch(values["pid"])):
            return url_for("console.participants")
        clean["pid"] = values["pid"]
    return url_for(endpoint, **clean)


def _done(endpoint: str, text: str | None = None, error: str | None = None, **values):
    """Post/redirect/get with a flashed message; a script's upload request (XHR) gets the address as JSON instead
    of a redirect, so that it can show progress and then load the page (and the message) itself. `values`: only
    ``date`` and ``pid`` (checked by :func:`_target`)."""
    if error:
        flash(_short(error), "error")
    elif text:
        flash(_short(text), "ok")
    url = _target(endpoint, values)
    if request.headers.get("X-Requested-With") == "XMLHttpRequest":
        return jsonify(next=url, ok=error is None)
    return redirect(url, 303)


def _act(endpoint: str, fn, ok, **values):
    """Run `fn(store)` as the signed-in researcher; flash `ok(result)` or the function's error."""
    try:
        with store(actor()) as s:
            r = fn(s)
    except UserError as exc:
        return _done(endpoint, error=str(exc), **values)
    return _done(endpoint, ok(r), **values)


# ---------------------------------------------------------------------------------------------- the day
@bp.get("/today")
@researcher
def today():
    from study.people.participants import list_participants
    from study.people.scheduling import DEFAULT_SIMULATOR, day_agenda

    day = request.args.get("date") or date.today().isoformat()
    try:
        with store() as s:
            agenda = day_agenda(s, day)
            people = list_participants(s)
    except UserError as exc:
        return _done("console.today", error=str(exc))
    phase = {r.participant_id: (r.phase if isinstance(r.phase, str) else None, r.phase_outcome)
             for r in people.itertuples(index=False)}
    soon = datetime.now() + timedelta(minutes=15)   # a bookable default start: the next quarter hour
    default_at = f"{day}T09:00" if day != f"{soon:%Y-%m-%d}" else f"{soon:%Y-%m-%dT%H}:{soon.minute // 15 * 15:02d}"
    return render_template("c_today.html", day=day, agenda=_records(agenda), phase=phase, default_at=default_at,
                           participants=people["participant_id"].tolist(), simulator=DEFAULT_SIMULATOR)


@bp.post("/book")
@researcher
def book():
    from study.people.scheduling import DEFAULT_SIMULATOR
    from study.people.scheduling import book as book_slot

    f = request.form
    return _act("console.today", lambda s: book_slot(s, f.get("participant_id", ""), f.get("at", ""),
                                                     simulator=f.get("simulator") or DEFAULT_SIMULATOR),
                lambda r: f"{r['participant_id']}: {r['simulator']} booked {when(r['starts_at'])}-"
                          f"{r['ends_at']:%H:%M}",
                date=f.get("at", "")[:10])


@bp.post("/appointment")
@researcher
def appointment():
    from study.people.scheduling import set_status

    f = request.form
    status = f.get("status", "")
    if status not in ("attended", "no_show", "cancelled"):
        return _done("console.today", error=f"unknown appointment status {status!r}", date=f.get("date"))
    return _act("console.today",
                lambda s: set_status(s, f.get("participant_id", ""), status, note=f.get("note") or None),
                lambda r: f"{r['participant_id']}: appointment {status.replace('_', '-')}", date=f.get("date"))


@bp.get("/calendar.ics")
@researcher
def calendar():
    """The booked appointments as an iCalendar file for the lab's calendar (`schedule export`)."""
    from study.people.scheduling import to_ics

    with store() as s:
        data = to_ics(s)
    return send_file(io.BytesIO(data), mimetype="text/calendar", as_attachment=True,
                     download_name="appointments.ics")


# ---------------------------------------------------------------------------------------------- participants
@bp.get("/participants")
@researcher
def participants():
    from study.people.participants import list_participants
    from study.store.studies import definition

    with store() as s:
        people = list_participants(s)
        study = definition(s)
    refill, g.researcher.refill = g.researcher.refill, {}  # a refused registration's values, shown once
    return render_template("c_participants.html", people=_records(people), columns=list(people.columns),
                           attributes=study.attributes, protocols=list(study.protocols), form=refill)


@bp.post("/participants")
@researcher
def register():
    from study.people.participants import add_participant
    from study.store.studies import definition

    f = request.form
    pid = f.get("participant_id", "").strip()
    names: list[str] = []
    try:
        with store(actor()) as s:
            names = [a.name for a in definition(s).attributes]
            attrs = {n: f[n] for n in names if f.get(n, "").strip()}  # an empty field = not given
            add_participant(s, pid, attrs, protocol=f.get("protocol") or None)
    except UserError as exc:  # the form comes back filled in: the values wait in the server-side session
        g.researcher.refill = {k: f[k] for k in ("participant_id", "protocol", *names)
                               if k in f and len(f[k]) <= REFILL_MAX}
        return _done("console.participants", error=str(exc))
    return _done("console.participant", f"participant {pid} added", pid=pid)


@bp.get("/p/<pid>")
@researcher
def participant(pid: str):
    from study.people.exclusions import REASONS, SCOPES, list_exclusions
    from study.people.participants import participant_attributes, require
    from study.people.protocol import protocol_of, status
    from study.store.studies import definition
    from study.webapp.occasion_rows import participant_occasions

    ins = state()["instrument"].name
    try:
        with store() as s:
            require(s, pid)
            proto = protocol_of(s, pid)
            phases = status(s, pid)
            exclusions = list_exclusions(s, pid)
            drives = s.df("SELECT condition, source, n_samples, duration_s, distance_m, file_name, created_at "
                          "FROM drives WHERE participant_id = ? ORDER BY condition", [pid])
            attrs = _records(participant_attributes(s, [pid]).drop(columns="participant_id"))[0]
            study = definition(s)
            occasions = participant_occasions(s, study, ins, pid, proto, phases)
    except UserError as exc:
        return _done("console.participants", error=str(exc))
    closed = "all" in set(exclusions["scope"])  # advance refuses then; no buttons that can only fail
    current = phases[phases["outcome"] == "in_progress"]
    pending = phases[phases["outcome"] == "pending"]
    drive_phases = [p for p in proto.steps if p.drive and p.condition]
    return render_template(
        "c_participant.html", pid=pid, protocol=proto.name, phases=_records(phases), closed=closed,
        current=None if current.empty else current.iloc[-1]["phase"],
        next_phase=None if pending.empty else pending.iloc[0]["phase"],
        exclusions=_records(exclusions), scopes=SCOPES, reasons=REASONS,
        drives=_records(drives), conditions=study.condition_names,
        drive_conditions=[p.condition for p in drive_phases], survey=occasions[0], occasions=occasions,
        attributes=attrs, upload_max_mb=DRIVE_UPLOAD_MAX // (1024 * 1024))


@bp.post("/p/<pid>/start")
@researcher
def start(pid: str):
    """Start the phase named in the form at the server's time (never a typed time); it completes the current one."""
    from study.people.protocol import advance

    phase = request.form.get("phase", "")
    return _act("console.participant", lambda s: advance(s, pid, phase, note=request.form.get("note") or None),
                lambda r: f"{pid}: {phase} started" + (f" ({r['completed']} completed)" if r["completed"] else ""),
                pid=pid)


@bp.post("/p/<pid>/end")
@researcher
def end(pid: str):
    from study.people.protocol import complete

    return _act("console.participant", lambda s: complete(s, pid, note=request.form.get("note") or None),
                lambda r: f"{pid}: {r} completed", pid=pid)


@bp.post("/p/<pid>/abort")
@researcher
def abort_phase(pid: str):
    from study.people.protocol import abort

    reason = request.form.get("reason", "")
    return _act("console.participant", lambda s: abort(s, pid, reason), lambda r: f"{pid}: {r} aborted ({reason})",
                pid=pid)


@bp.post("/p/<pid>/exclude")
@researcher
def exclude(pid: str):
    from study.people.exclusions import exclude as record

    f = request.form
    return _act("console.participant",
                lambda s: record(s, pid, f.get("scope", ""), f.get("reason", ""), note=f.get("note") or None),
                lambda r: f"{pid}: excluded ({r['scope']}, {r['reason']})", pid=pid)


@bp.post("/p/<pid>/exclude/revoke")
@researcher
def unexclude(pid: str):
    from study.people.exclusions import revoke

    scope = request.form.get("scope", "")
    return _act("console.participant", lambda s: revoke(s, pid, scope), lambda r: f"{pid}: exclusion ({scope}) revoked",
                pid=pid)


@bp.post("/p/<pid>/link/revoke")
@researcher
def revoke_link(pid: str):
    from study.store.studies import definition
    from study.survey import answers as sv
    from study.webapp.occasion_rows import occasion_field

    def revoke(s):
        occasion = occasion_field(definition(s), request.form.get("occasion"))
        sv.revoke_links(s, pid, None if occasion else state()["instrument"].name, occasion)
        return occasion

    return _act("console.participant", revoke,
                lambda occasion: f"{pid}: survey link{f' of {occasion}' if occasion else ''} revoked", pid=pid)


@bp.post("/p/<pid>/drive")
@researcher
def upload_drive(pid: str):
    """A drive-log upload, imported exactly as `drive import` does (format from the file name or chosen, the study's
    log mapping, plausibility checks, `force` with a reason, `replace`). Memory stays small for a large log: the web
    server spools the body to disk beyond 500 KB, it is copied to a temporary file, and a canonical CSV or Parquet
    log is imported from there in chunks (docs/store.md, "Drive logs")."""
    from study.logs.importing import import_drive_file

    f = request.form
    upload = request.files.get("file")
    name = upload_name(upload.filename or "") if upload else ""
    if not name:
        return _done("console.participant", error="choose a drive-log file to upload", pid=pid)
    steps: list[str] = []
    with tempfile.TemporaryDirectory(prefix="pedas-upload-") as tmp:
        path = Path(tmp) / name  # made safe and short, it sets the format; the client's name is stored, never a path
        upload.save(path)
        try:
            with store(actor()) as s:
                r = import_drive_file(s, pid, f.get("condition", ""), path, replace=bool(f.get("replace")),
                                      progress=steps.append, fmt=f.get("format") or None,
                                      vehicle=f.get("vehicle") or None, force=f.get("force") or None,
                                      original_name=upload.filename)
        except UserError as exc:
            return _done("console.participant", error=str(exc), pid=pid)
    if r.status == "unchanged":
        return _done("console.participant", f"{pid} {r.condition}: unchanged (the same log is already stored)", pid=pid)
    forced = f"; imported despite: {'; '.join(r.overridden)}" if r.overridden else ""
    return _done("console.participant", f"{pid} {r.condition}: {r.status} drive {r.drive_id}, {r.n_samples} samples "
                 f"in {r.seconds:.2f} s ({'; '.join(steps)}){forced}", pid=pid)


# ---------------------------------------------------------------------------------------------- the study
@bp.get("/completeness")
@researcher
def completeness():
    from study.survey.completeness import completeness as table

    with store() as s:
        df = table(s, state()["instrument"].name)
    return render_template("c_completeness.html", rows=_records(df),
                           n_complete=int(df["complete"].sum()), n=len(df))


@bp.get("/export")
@researcher
def export_form():
    return render_template("c_export.html")


@bp.post("/export")
@researcher
def export():
    """Every table as `export` writes it (csv | parquet | sav, optionally de-identified), as one ZIP download."""
    from study.export.writer import export as write
    from study.store.studies import definition

    fmt, deid = request.form.get("format", ""), bool(request.form.get("deidentify"))
    buf = io.BytesIO()
    with tempfile.TemporaryDirectory(prefix="pedas-export-") as tmp:
        try:
            with store(actor()) as s:
                r = write(s, fmt, tmp, deidentify=deid)
                study_id = definition(s).study_id
        except UserError as exc:
            return _done("console.export_form", error=str(exc))
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            for name in sorted([*r.files, "manifest.json"]):
                if deid:  # the entries' times would tell when the export was made: a fixed one instead
                    z.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)),
                               (Path(tmp) / name).read_bytes(), zipfile.ZIP_DEFLATED)
                else:
                    z.write(Path(tmp) / name, name)
    buf.seek(0)
    stamp = date.today().isoformat()
    return send_file(buf, mimetype="application/zip", as_attachment=True,
                     download_name=f"{study_id}-{fmt}{'-deidentified' if deid else ''}-{stamp}.zip")
