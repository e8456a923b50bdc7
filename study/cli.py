"""`pedas-study`: the command-line interface, a thin layer over the public functions of the three packages.

Each command module exposes ``register(cli: Cli)`` and adds its commands with :meth:`Cli.command` (a top-level
command such as ``init``) or :meth:`Cli.group` (a sub-command under a shared group such as ``bench mpc``).
Handlers take the parsed ``argparse.Namespace`` and return an exit code (``None`` means 0). Heavy imports stay
inside the handlers so that ``--help`` and small commands start fast.

Errors: any exception reaching :func:`main` is printed as one line ``pedas-study: error: ...`` and the process
exits non-zero (2 for bad input, 1 for anything unexpected). ``PEDAS_STUDY_DEBUG=1`` shows the traceback.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from pathlib import Path
from typing import Callable, Sequence

DEFAULT_DB = Path("data") / "study.duckdb"

# The command modules, in the order their commands appear in --help. The CLI is the top layer: it may import
# every package, while the packages keep their one-way imports (analysis -> study -> pedas).
COMMAND_MODULES: tuple[str, ...] = (
    "study.commands",        # init, participant, session, exclude, drive import, export
    "study.survey_cli",      # survey import | serve | link | entry ...
    "study.schedule_cli",    # session schedule, schedule day | export
    "study.simulate_cli",    # drive simulate, simulate cohort
    "pedas.cli_core",        # kpi energy, bench mpc
    "pedas.cli_drive",       # bench drive
    "analysis.cli_survey",   # analyze survey
    "analysis.cli_drives",   # analyze drives, bench kpi
    "analysis.cli_paper",    # paper audit | reconstruct
    "analysis.cli_report",   # report
)

Handler = Callable[[argparse.Namespace], "int | None"]


class Cli:
    """Collects the commands of all modules into one argparse parser."""

    def __init__(self, parser: argparse.ArgumentParser) -> None:
        self.parser = parser
        self._top = parser.add_subparsers(dest="command", metavar="COMMAND")
        self._top.required = True
        self._groups: dict[str, argparse._SubParsersAction] = {}

    def command(self, name: str, help: str, handler: Handler | None = None) -> argparse.ArgumentParser:
        """Add a top-level command ``pedas-study NAME``."""
        p = self._top.add_parser(name, help=help, description=help)
        if handler is not None:
            p.set_defaults(func=handler)
        return p

    def group(self, name: str, help: str = "") -> argparse._SubParsersAction:
        """The sub-command table of ``pedas-study NAME ...``, created on first use and shared by modules."""
        if name not in self._groups:
            p = self._top.add_parser(name, help=help, description=help)
            sub = p.add_subparsers(dest=f"{name}_command", metavar="SUBCOMMAND")
            sub.required = True
            self._groups[name] = sub
        return self._groups[name]

    def subcommand(self, group: str, name: str, help: str, handler: Handler | None = None,
                   group_help: str = "") -> argparse.ArgumentParser:
        """Add ``pedas-study GROUP NAME``."""
        p = self.group(group, group_help).add_parser(name, help=help, description=help)
        if handler is not None:
            p.set_defaults(func=handler)
        return p


def db_path(args: argparse.Namespace) -> Path:
    """The store chosen by ``--db``, else ``PEDAS_STUDY_DB``, else ``data/study.duckdb``."""
    if getattr(args, "db", None):
        return Path(args.db)
    env = os.environ.get("PEDAS_STUDY_DB")
    return Path(env) if env else DEFAULT_DB


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pedas-study",
        description="Driving-simulator user studies of the pEDAS eco-driving assistance system.",
    )
    parser.add_argument("--db", metavar="PATH", default=None,
                        help=f"study store (DuckDB file); default $PEDAS_STUDY_DB or {DEFAULT_DB}")
    parser.add_argument("--actor", default=None,
                        help="who is acting, recorded in the audit log (default $PEDAS_STUDY_ACTOR or the OS user)")
    cli = Cli(parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(cli)
    return parser


def _exit_code(exc: BaseException) -> int:
    return 2 if isinstance(exc, (ValueError, KeyError, LookupError, FileNotFoundError, FileExistsError,
                                 PermissionError)) else 1


def _one_line(exc: BaseException) -> str:
    msg = str(exc).strip() or type(exc).__name__
    if isinstance(exc, KeyError) and exc.args:
        msg = str(exc.args[0])
    return " ".join(msg.split())


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except KeyboardInterrupt:
        print("pedas-study: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one line for the user; the traceback on request
        if os.environ.get("PEDAS_STUDY_DEBUG"):
            traceback.print_exc()
        print(f"pedas-study: error: {_one_line(exc)}", file=sys.stderr)
        return _exit_code(exc)
    return int(code or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
