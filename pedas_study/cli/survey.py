"""`pedas-study survey ...`: import, web form, participant links, double-entry discrepancies and resolution."""
from __future__ import annotations

import os

from pedas_study.cli.bulk import add_ignore_option
from pedas_study.cli.common import add_format_option, format_frame, open_store

PASSWORD_ENV = "PEDAS_SURVEY_PASSWORD"


def _import(args):
    from study.survey.survey_import import import_survey

    from study.common.errors import split_names

    with open_store(args) as st:
        r = import_survey(st, args.file, entry=args.entry, instrument=args.instrument, occasion=args.occasion,
                          ignore_columns=split_names(args.ignore_columns))
    kind = f"entry round {r.entry_round} of a double entry" if r.double_entry else "single electronic entry (final)"
    at = (f" at {len(r.occasions)} occasions ({', '.join(r.occasions)}; {r.questionnaires} questionnaires)"
          if len(r.occasions) > 1 else "")
    print(f"imported {r.participants} participants{at} ({r.answers} answers, {r.missing} missing) as {kind}")


def _link(args):
    from study.survey import answers as sv

    with open_store(args) as st:
        token = sv.issue_link(st, args.participant_id, args.instrument, args.occasion)
    print(f"{args.base_url.rstrip('/')}/s/{token}")


def _revoke(args):
    from study.survey import answers as sv

    with open_store(args) as st:
        n = sv.revoke_links(st, args.participant_id, args.instrument, args.occasion)
    print(f"{args.participant_id}: {n} survey link{'s' if n != 1 else ''} revoked")


def _status(args):
    from study.survey import answers as sv

    with open_store(args, read_only=True) as st:
        df = sv.survey_status(st, args.instrument, args.occasion)
    print(format_frame(df, args.format))


def _discrepancies(args):
    from study.survey import answers as sv

    with open_store(args, read_only=True) as st:
        df = sv.discrepancies(st, args.instrument, args.occasion)
    print(format_frame(df, args.format))


def _resolve(args):
    from study.survey import answers as sv

    with open_store(args) as st:
        a = sv.resolve(st, args.participant_id, args.item_id, args.value, args.note, args.instrument, args.occasion)
    shown = a.text if a.text is not None else ("missing" if a.value is None else a.value)
    print(f"{args.participant_id} {args.item_id}: final value {shown}")


def _final(args):
    from pathlib import Path

    from study.survey import answers as sv

    with open_store(args, read_only=True) as st:
        df = sv.final_responses(st, args.instrument, args.occasion)
    for item in df.columns[1:]:
        col = df[item]
        if col.dtype == "float64" and (col.dropna() % 1 == 0).all():
            df[item] = col.astype("Int64")  # whole numbers as ticked: "4", not "4.0"
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False, lineterminator="\n")
    rows = f"{len(df)} rows ({df['participant_id'].nunique()} participants)" if "occasion" in df else \
        f"{len(df)} participants"
    print(f"wrote {rows} to {out}")


def _scores(args):
    from study.common.errors import split_names
    from study.export.writer import write_scores

    formats = split_names(args.format) or ("csv",)
    if "sav" in formats:
        import pyreadstat  # noqa: F401  (loaded before the store is held)
    with open_store(args, read_only=True) as st:
        written = write_scores(st, args.out, formats)
    for path, n in written.items():
        print(f"wrote {n} rows of scores to {path}")


def _serve(args):
    import secrets
    import signal
    import threading

    from study.webapp import SurveyServer, create_app
    from study.webapp.signin import SignInSettings

    password = os.environ.get(PASSWORD_ENV)
    generated = not password
    if generated:
        password = secrets.token_urlsafe(12)
    with open_store(args) as st:  # checked and closed again: each request opens the store while it runs
        settings = SignInSettings(trust_proxy=args.trust_proxy,
                                  secure_cookies="always" if args.secure_cookies else "auto")
        app = create_app(st, password, instrument=args.instrument, signin=settings)
    server = SurveyServer(app, args.host, args.port)
    print(f"survey form on {server.url}/  (researcher pages: {server.url}/r/)", flush=True)
    if generated:
        print(f"researcher password (set {PASSWORD_ENV} to choose one): {password}", flush=True)
    if args.host not in ("127.0.0.1", "localhost", "::1") and not args.trust_proxy:
        print(f"warning: bound to {args.host}: reachable from other machines; plain HTTP", flush=True)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    server.start()
    try:
        stop.wait()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    print("survey server stopped")


def _instrument_option(p, occasion: str = "the instrument's only one") -> None:
    p.add_argument("--instrument", default=None, help="instrument name (default: the study's instrument, or the "
                                                      "occasion's)")
    if occasion:
        p.add_argument("--occasion", default=None, metavar="PHASE",
                       help=f"the questionnaire phase answered in (default: {occasion})")


def register(cli) -> None:
    """Declare the `survey` group."""
    g = cli.group("survey", "survey instrument, web form and data entry")
    p = g.command("import", "import a survey CSV, wide or long, with or without an occasion or condition column "
                  "(docs/survey.md), all or nothing", _import)
    p.add_argument("file", metavar="FILE")
    p.add_argument("--entry", type=int, choices=(1, 2), default=None,
                   help="paper-form double entry round; without it the file is a single electronic entry (final)")
    _instrument_option(p, "the file's occasion or condition column, else the instrument's only one")
    add_ignore_option(p)

    p = g.command("serve", "run the survey web form (participant links + researcher data entry)", _serve)
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--trust-proxy", type=int, default=0, metavar="N",
                   help="behind N reverse proxies (TLS): believe their X-Forwarded-For/-Proto (default 0)")
    p.add_argument("--secure-cookies", action="store_true",
                   help="always mark the session cookie Secure (default: when the request came over HTTPS)")
    _instrument_option(p, "")

    p = g.command("link", "issue a one-time survey link for a participant (revokes earlier ones)", _link)
    p.add_argument("participant_id", metavar="ID")
    p.add_argument("--base-url", default="http://127.0.0.1:8000", help="address of `survey serve` (default %(default)s)")
    _instrument_option(p, "the instrument's only one, else the questionnaire phase the participant is in")

    p = g.command("revoke", "revoke a participant's survey link (a new one can be issued later)", _revoke)
    p.add_argument("participant_id", metavar="ID")
    _instrument_option(p)

    p = g.command("status", "per participant: link, entries, discrepancies, final", _status)
    add_format_option(p)
    _instrument_option(p, "every occasion of the instrument")

    p = g.command("discrepancies", "every item where double entry 1 and 2 differ", _discrepancies)
    add_format_option(p)
    _instrument_option(p, "every occasion of the instrument")

    p = g.command("resolve", "record the final value of a double-entry discrepancy (audited)", _resolve)
    p.add_argument("participant_id", metavar="ID")
    p.add_argument("item_id", metavar="ITEM")
    p.add_argument("value", metavar="VALUE", help="the value on the paper form; '' = not answered")
    p.add_argument("--note", default=None)
    _instrument_option(p)

    p = g.command("scores", "write every declared score per participant and occasion (and the rated condition) "
                            "as CSV, Parquet or SPSS .sav with labels", _scores)
    p.add_argument("--out", required=True, metavar="DIR", help="the folder of scores.<format>")
    p.add_argument("--format", default="csv", metavar="FORMATS",
                   help="csv, parquet, sav or several, comma-separated (default csv)")
    p = g.command("final", "write the final answers as a wide CSV (survey CSV of docs/contracts.md)", _final)
    p.add_argument("--out", required=True, metavar="CSV")
    _instrument_option(p, "every occasion of the instrument, one row per participant and occasion")
