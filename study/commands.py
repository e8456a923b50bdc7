"""CLI commands of the store part: init, participant, session, exclude, drive import/list, export.

Handlers are thin: they open the store, call one public function and print its result.
"""
from __future__ import annotations

import argparse
import sys

from study.errors import UserError

LIST_FORMATS = ("table", "csv", "json")


def format_frame(df, fmt: str = "table") -> str:
    """A DataFrame as text: an aligned table, CSV or JSON records (ISO dates)."""
    if fmt == "csv":
        return df.to_csv(index=False).rstrip("\n")
    if fmt == "json":
        return df.to_json(orient="records", date_format="iso", indent=1)
    if df.empty:
        return "(none)"
    shown = df.astype(object).where(df.notna(), "-")
    for col in shown.columns:
        shown[col] = shown[col].map(lambda x: f"{x:%Y-%m-%d %H:%M:%S}" if hasattr(x, "strftime") else
                                    (f"{x:.1f}" if isinstance(x, float) else x))
    return shown.to_string(index=False)


def _open(args, must_exist: bool = True, read_only: bool = False):
    from study.cli import db_path
    from study.store import Store

    path = db_path(args)
    if must_exist and not path.exists():
        raise UserError(f"no store at {path} (run `pedas-study init` first)")
    return Store.open(path, actor=args.actor, read_only=read_only)


# ---------------------------------------------------------------------------------------------- init
def _init(args) -> None:
    from study.cli import db_path

    existed = db_path(args).exists()
    with _open(args, must_exist=False) as st:
        what = "created" if not existed else "upgraded" if st.applied else "up to date"
        print(f"store {st.path} {what} (schema v{st.schema_version})")


# ---------------------------------------------------------------------------------------------- participants
def _participant_add(args) -> None:
    from study.participants import add_participant

    with _open(args) as st:
        row = add_participant(st, args.id, age=args.age, gender=args.gender, license_years=args.license_years,
                              style=args.style, eco_familiarity=args.eco_familiarity, protocol=args.protocol)
    print(f"participant {row['participant_id']} added")


def _participant_list(args) -> None:
    from study.participants import list_participants

    with _open(args) as st:
        print(format_frame(list_participants(st), args.format))


# ---------------------------------------------------------------------------------------------- session
def _session_advance(args) -> None:
    from study.protocol import advance

    with _open(args) as st:
        r = advance(st, args.id, args.phase, note=args.note, at=args.at)
    done = f" ({r['completed']} completed)" if r["completed"] else ""
    print(f"{args.id}: {r['started']} started{done}")


def _session_abort(args) -> None:
    from study.protocol import abort

    with _open(args) as st:
        phase = abort(st, args.id, args.reason, at=args.at)
    print(f"{args.id}: {phase} aborted ({args.reason})")


def _session_complete(args) -> None:
    from study.protocol import complete

    with _open(args) as st:
        phase = complete(st, args.id, note=args.note, at=args.at)
    print(f"{args.id}: {phase} completed")


def _session_status(args) -> None:
    import json

    from study.exclusions import list_exclusions
    from study.protocol import protocol_of, status

    with _open(args) as st:
        proto = protocol_of(st, args.id)
        df = status(st, args.id)
        exc = list_exclusions(st, args.id)
        drives = st.df("SELECT condition, source, n_samples FROM drives WHERE participant_id = ? ORDER BY condition",
                       [args.id])
    if args.format == "json":
        print(json.dumps({"participant_id": args.id, "protocol": proto.name,
                          "phases": json.loads(df.to_json(orient="records", date_format="iso")),
                          "exclusions": json.loads(exc.to_json(orient="records", date_format="iso")),
                          "drives": json.loads(drives.to_json(orient="records"))}, indent=1))
        return
    if args.format == "csv":
        print(format_frame(df, "csv"))
        return
    print(f"{args.id} (protocol {proto.name})")
    print(format_frame(df.drop(columns=["seq"]), "table"))
    if exc.empty:
        print("exclusions: none")
    for r in exc.itertuples(index=False):
        print(f"excluded: scope {r.scope}, reason {r.reason}" + (f" ({r.note})" if isinstance(r.note, str) else ""))
    print("drives: " + (", ".join(f"{r.condition} ({r.n_samples} samples, {r.source})"
                                  for r in drives.itertuples(index=False)) or "none"))


# ---------------------------------------------------------------------------------------------- exclusions
def _exclude(args) -> None:
    from study.exclusions import exclude, revoke

    with _open(args) as st:
        if args.revoke:
            revoke(st, args.id, args.scope)
            print(f"{args.id}: exclusion ({args.scope}) revoked")
            return
        if not args.reason:
            raise UserError("--reason is required (motion_sickness|technical_issue|incomplete_survey|withdrawn|other)")
        exclude(st, args.id, args.scope, args.reason, note=args.note)
    print(f"{args.id}: excluded ({args.scope}, {args.reason})")


# ---------------------------------------------------------------------------------------------- drives
def _drive_import(args) -> None:
    from study.drives import import_drive_file

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    with _open(args) as st:
        r = import_drive_file(st, args.id, args.condition, args.file, replace=args.replace, route=args.route,
                              progress=progress if args.verbose else None)
    extra = f"; ignored columns: {', '.join(r.ignored_columns)}" if r.ignored_columns else ""
    if r.status == "unchanged":
        print(f"{args.id} {args.condition}: unchanged (same log already stored as drive {r.drive_id})")
    else:
        print(f"{args.id} {args.condition}: {r.status} drive {r.drive_id}, {r.n_samples} samples "
              f"in {r.seconds:.2f} s ({r.rows_per_second:,.0f} rows/s){extra}")


def _drive_list(args) -> None:
    from study.drives import list_drives

    with _open(args) as st:
        print(format_frame(list_drives(st), args.format))


# ---------------------------------------------------------------------------------------------- export
def _export(args) -> None:
    from study.export import export

    with _open(args) as st:
        r = export(st, args.format, args.outdir, deidentify=args.deidentify)
    total = sum(r.files.values())
    left = f"; left out: {', '.join(r.skipped)}" if r.skipped else ""
    print(f"exported {len(r.files)} files ({total} rows) to {r.outdir}{left}")


def _bench_import(args) -> None:
    import json

    from study.bench_import import bench_import

    r = bench_import(rows=args.rows, repeats=args.repeats)
    if args.json:
        print(json.dumps(r.as_dict(), indent=1))
        return
    print(f"drive import of a {r.rows:,}-row Parquet log, median of {r.repeats}: {r.import_s_median:.2f} s "
          f"({r.import_rows_per_s:,.0f} rows/s); DuckDB read_parquet peer {r.peer_s_median:.2f} s "
          f"({r.peer_rows_per_s:,.0f} rows/s); ratio {r.ratio:.1f}x")


def _add_time(p: argparse.ArgumentParser) -> None:
    p.add_argument("--at", metavar="ISO_TIME", default=None,
                   help="when it happened (ISO 8601, UTC unless an offset is given); default now")


def register(cli) -> None:
    """Add this module's commands to the `pedas-study` parser."""
    from pedas.vocabulary import CONDITIONS
    from study.exclusions import REASONS, SCOPES
    from pedas.vocabulary import STYLES
    from study.participants import GENDERS

    cli.command("init", "create the study store (or upgrade its schema)", _init)

    p = cli.subcommand("participant", "add", "register a participant (pseudonymous ID such as P001)",
                       _participant_add, group_help="register and list participants")
    p.add_argument("id", metavar="ID")
    p.add_argument("--age", type=int)
    p.add_argument("--gender", choices=GENDERS)
    p.add_argument("--license-years", type=int, dest="license_years")
    p.add_argument("--style", choices=STYLES, help="self-reported driving style")
    p.add_argument("--eco-familiarity", type=int, choices=range(1, 6), dest="eco_familiarity",
                   metavar="1-5", help="1 never heard of eco-driving ... 5 uses a similar system regularly")
    p.add_argument("--protocol", default=None, help="protocol file name (default paper_v1)")
    p = cli.subcommand("participant", "list", "list participants with protocol position and exclusions",
                       _participant_list)
    p.add_argument("--format", choices=LIST_FORMATS, default="table")

    grp = "walk a participant through the protocol phases"
    p = cli.subcommand("session", "advance", "start the next protocol phase (completes the one in progress)",
                       _session_advance, group_help=grp)
    p.add_argument("id", metavar="ID")
    p.add_argument("phase", metavar="PHASE", help="familiarisation, baseline_drive, pedas_intro, practice, "
                                                   "pedas_drive, survey (in this order)")
    p.add_argument("--note", default=None)
    _add_time(p)
    p = cli.subcommand("session", "abort", "abort the phase in progress (e.g. motion sickness)", _session_abort,
                       group_help=grp)
    p.add_argument("id", metavar="ID")
    p.add_argument("--reason", required=True)
    _add_time(p)
    p = cli.subcommand("session", "complete", "complete the phase in progress without starting another",
                       _session_complete, group_help=grp)
    p.add_argument("id", metavar="ID")
    p.add_argument("--note", default=None)
    _add_time(p)
    p = cli.subcommand("session", "status", "each phase with start, end and outcome; exclusions; drives",
                       _session_status, group_help=grp)
    p.add_argument("id", metavar="ID")
    p.add_argument("--format", choices=LIST_FORMATS, default="table")

    p = cli.command("exclude", "exclude a participant from analyses (scope all|objective|subjective)", _exclude)
    p.add_argument("id", metavar="ID")
    p.add_argument("--scope", choices=SCOPES, required=True,
                   help="all: no data used; objective: drive KPIs not used; subjective: survey not used")
    p.add_argument("--reason", choices=REASONS)
    p.add_argument("--note", default=None)
    p.add_argument("--revoke", action="store_true", help="withdraw the exclusion with this scope")

    p = cli.subcommand("drive", "import", "import a simulator drive log (CSV or Parquet) for a participant",
                       _drive_import, group_help="drive logs")
    p.add_argument("id", metavar="ID")
    p.add_argument("condition", choices=CONDITIONS)
    p.add_argument("file", metavar="FILE")
    p.add_argument("--replace", action="store_true", help="replace a different log stored for this drive")
    p.add_argument("--route", default=None, help="route name stored with the drive")
    p.add_argument("--verbose", "-v", action="store_true", help="report progress on stderr")
    p = cli.subcommand("drive", "list", "list stored drives", _drive_list, group_help="drive logs")
    p.add_argument("--format", choices=LIST_FORMATS, default="table")

    p = cli.subcommand("bench", "import", "throughput of drive-log import (rows/s) vs a plain DuckDB load",
                       _bench_import, group_help="benchmarks")
    p.add_argument("--rows", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", action="store_true")

    p = cli.command("export", "export every table as CSV, Parquet or SPSS .sav", _export)
    p.add_argument("format", choices=("csv", "parquet", "sav"))
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("--deidentify", action="store_true",
                   help="age and licence years as bands, no notes or names, no audit log")
