"""Helpers shared by the command modules: the store a command works on, tables as text, which errors are bad
input."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from study.common.errors import UserError

DEFAULT_DB = Path("data") / "study.duckdb"
LIST_FORMATS = ("table", "csv", "json")
DRIVE_CACHE_HELP = "cache of simulated drives (default $PEDAS_DRIVE_CACHE or .report-cache/drives)"
# the errors that mean bad input (exit code 2): UserError is a ValueError; the others are a path given on the
# command line that is missing, a directory where a file is meant (or the reverse), unreadable or unwritable
USER_ERRORS: tuple[type[BaseException], ...] = (ValueError, FileNotFoundError, IsADirectoryError,
                                                NotADirectoryError, PermissionError, FileExistsError)


def is_user_error(exc: BaseException) -> bool:
    """True for bad input (exit code 2), False for a bug (exit code 1)."""
    return isinstance(exc, USER_ERRORS)


def db_path(args: argparse.Namespace) -> Path:
    """The store chosen by ``--db``, else ``PEDAS_STUDY_DB``, else ``data/study.duckdb``."""
    if getattr(args, "db", None):
        return Path(args.db)
    env = os.environ.get("PEDAS_STUDY_DB")
    return Path(env) if env else DEFAULT_DB


def open_store(args: argparse.Namespace, must_exist: bool = True, read_only: bool = False):
    """The store of :func:`db_path`, opened as ``--actor``; UserError "no store at ..." when it does not exist
    (unless ``must_exist=False``, which creates it).

    Another process (the survey server, another command) cannot open the store while a command holds it, so a
    handler imports what it uses before it calls this and closes the store before it formats and prints its
    output. This imports what nearly every command uses once the store is open, the reader of the stored study
    (:func:`study.store.studies.definition`, which needs no pandas), before opening it."""
    import study.store.studies  # noqa: F401 - loaded before the store is held, not while
    from study.store.store import Store

    path = db_path(args)
    if must_exist and not path.exists():
        raise UserError(f"no store at {path} (run `pedas-study init --study DIR` first)")
    return Store.open(path, actor=getattr(args, "actor", None), read_only=read_only)


def add_format_option(p: argparse.ArgumentParser) -> None:
    """``--format table|csv|json`` of a listing command."""
    p.add_argument("--format", choices=LIST_FORMATS, default="table")


def format_frame(df, fmt: str = "table") -> str:
    """A DataFrame as text: an aligned table (missing values as "-", floats with one decimal, times to the
    second), CSV or JSON records (ISO dates). :func:`pedas_study.cli.rows_text.format_rows` prints rows of Python
    values the same way without pandas."""
    if fmt == "csv":
        return df.to_csv(index=False).rstrip("\n")
    if fmt == "json":
        return df.to_json(orient="records", date_format="iso", indent=1)
    if df.empty:
        return "(none)"
    shown = df.astype(object).where(df.notna(), "-")
    for col in shown.columns:
        # the year padded by hand: C strftime prints year 1 as "1"
        shown[col] = shown[col].map(lambda x: x.strftime(f"{getattr(x, 'year', 1900):04d}-%m-%d %H:%M:%S")
                                    if hasattr(x, "strftime") else
                                    (f"{x:.1f}" if isinstance(x, float) else x))
    return shown.to_string(index=False)


def simulate_and_store(args, tasks, **simulate_kw) -> list:
    """Simulate `tasks` (:func:`pedas.cohort.simulate_cohort`), store them in one transaction, print one line per
    drive; the stored (task, log, result) triples."""
    from pedas.cohort import simulate_cohort
    from study.logs.simulated import store_simulated, summary_line

    results = simulate_cohort(tasks, cache_dir=args.cache_dir, **simulate_kw)
    with open_store(args) as st:
        stored = store_simulated(st, tasks, results, replace=args.replace)
    for task, df, r in stored:
        print(summary_line(task, df, r))
    return stored


def add_scenario_option(p) -> None:
    """`--scenario NAME`: the traffic scenario of the simulated drives (pedas.scenario)."""
    from pedas.scenario import DEFAULT_SCENARIO, SCENARIOS

    known = "; ".join(sc.description for sc in SCENARIOS.values())
    p.add_argument("--scenario", default=DEFAULT_SCENARIO, metavar="NAME",
                   help=f"traffic scenario of the simulated drives (default {DEFAULT_SCENARIO}; {known}; "
                        "docs/route_and_traffic.md)")


def scenario_of(args, option: str = "scenario") -> str:
    """The scenario name given by `--scenario` (or another option); UserError (one line, exit 2) if unknown."""
    from pedas.scenario import get_scenario

    try:
        return get_scenario(getattr(args, option)).name
    except ValueError as exc:
        raise UserError(f"--{option.replace('_', '-')}: {exc}") from None
