"""`pedas-study`: the command line, a thin layer over the public functions of `study`, `pedas` and `analysis`.

One module per top-level command word, listed in `COMMAND_MODULES` in the order of ``--help``. Each exposes
``register(cli: Cli)`` and declares its command with :meth:`Cli.command` (``pedas-study init``) or its group with
:meth:`Cli.group` (``pedas-study bench mpc``), once: a second declaration of a name is an error. Handlers take the
parsed ``argparse.Namespace`` and return an exit code (``None`` means 0). Heavy imports stay inside the handlers
so that ``--help`` and small commands start fast: building the parser loads no numeric, statistics, units or
plotting library (tests/cli/test_cli_imports.py), and defaults a help text shows come from light modules
(``study.people.defaults``). A handler opens the store after its imports and closes it before printing
(:func:`pedas_study.cli.common.open_store`).

Errors: an exception reaching :func:`main` is printed as one line ``pedas-study: error: ...``. Bad input exits 2:
``ValueError`` (with ``study.common.errors.UserError``), the file-system errors of a bad path (missing, a directory, no
permission) and argparse's usage errors, which are one line too (``pedas-study session advance: error: the
following arguments are required: PHASE (see `pedas-study session advance --help`)``), not argparse's usage
dump. Anything else is a bug: exit 1, ``pedas-study: error: internal error: ...``. ``PEDAS_STUDY_DEBUG=1`` shows
the traceback.
Output into a pipe whose reader stopped (``... | head``) ends the command quietly with exit 0.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import re
import signal
import sys
import threading
import traceback
from typing import Callable, Sequence

from pedas_study.cli.common import DEFAULT_DB, is_user_error
from study.common.errors import UserError

COMMAND_MODULES: tuple[str, ...] = tuple(f"pedas_study.cli.{name}" for name in (
    "init", "study", "participant", "session", "exclude", "drive", "export",   # the study and its store
    "survey", "schedule", "simulate",                                  # survey, appointments, virtual cohort
    "hud", "live",                                                     # the HUD, live advice for a simulator
    "kpi", "analyze", "paper", "report", "plan",                       # analysis
    "bench",                                                           # benchmarks
))

LOG_ENV = "PEDAS_STUDY_LOG"
Handler = Callable[[argparse.Namespace], "int | None"]


class UsageError(UserError):
    """A command line argparse refuses (exit 2, one line)."""


class Parser(argparse.ArgumentParser):
    """argparse with its usage errors raised as :class:`UsageError` (one line naming the command and its
    ``--help``) instead of printing the usage and exiting; sub-parsers are of this class too."""

    def error(self, message: str):
        raise UsageError(f"{self.prog}: {message} (see `{self.prog} --help`)")


class Group:
    """The sub-commands of one group, ``pedas-study GROUP NAME``."""

    def __init__(self, name: str, parser: argparse.ArgumentParser) -> None:
        self._sub = parser.add_subparsers(dest=f"{name}_command", metavar="SUBCOMMAND")
        self._sub.required = True

    def command(self, name: str, help: str, handler: Handler | None = None) -> argparse.ArgumentParser:
        """Add ``pedas-study GROUP NAME``."""
        p = self._sub.add_parser(name, help=help, description=help)
        if handler is not None:
            p.set_defaults(func=handler)
        return p

    @property
    def commands(self) -> dict[str, argparse.ArgumentParser]:
        """Sub-command name -> its parser, in declaration order."""
        return dict(self._sub.choices)


class Cli:
    """The registry: every top-level command and group of `pedas-study` and the module that declared it."""

    def __init__(self, parser: argparse.ArgumentParser) -> None:
        self.parser = parser
        self._top = parser.add_subparsers(dest="command", metavar="COMMAND")
        self._top.required = True
        self.owners: dict[str, str] = {}     # top-level name -> module that declared it
        self.groups: dict[str, Group] = {}
        self._module = "?"

    def register(self, module: str) -> None:
        """Import a command module and let it declare its commands."""
        self._module = module
        try:
            importlib.import_module(module).register(self)
        finally:
            self._module = "?"

    def _add(self, name: str, help: str) -> argparse.ArgumentParser:
        if name in self.owners:
            raise RuntimeError(f"`pedas-study {name}` declared twice: in {self.owners[name]} and {self._module}")
        self.owners[name] = self._module
        return self._top.add_parser(name, help=help, description=help)

    def command(self, name: str, help: str, handler: Handler | None = None) -> argparse.ArgumentParser:
        """Declare the top-level command ``pedas-study NAME``."""
        p = self._add(name, help)
        if handler is not None:
            p.set_defaults(func=handler)
        return p

    def group(self, name: str, help: str) -> Group:
        """Declare the group ``pedas-study NAME SUBCOMMAND``; add its sub-commands with :meth:`Group.command`."""
        group = Group(name, self._add(name, help))
        self.groups[name] = group
        return group


def build_cli() -> Cli:
    """The registry with every command module registered."""
    parser = Parser(
        prog="pedas-study",
        description="Driving-simulator user studies: participants and protocol, drive logs, questionnaires, their "
                    "analysis and the report, for the study a store serves (docs/study_folder.md).",
    )
    parser.add_argument("--db", metavar="PATH", default=None,
                        help=f"study store (DuckDB file); default $PEDAS_STUDY_DB or {DEFAULT_DB}")
    parser.add_argument("--actor", default=None,
                        help="who is acting, recorded in the audit log (default $PEDAS_STUDY_ACTOR or the OS user)")
    cli = Cli(parser)
    for module in COMMAND_MODULES:
        cli.register(module)
    return cli


def build_parser() -> argparse.ArgumentParser:
    """The `pedas-study` argument parser."""
    return build_cli().parser


def error_line(exc: BaseException) -> str:
    """The one line printed for an exception: its message for bad input, else marked as an internal error."""
    from study.common.errors import escaped

    # one line: runs of blanks and line breaks become a space, other control characters (a CR in a file
    # name) are shown escaped rather than hidden
    text = escaped(re.sub(r"[ \t\n]+", " ", str(exc)).strip())
    if isinstance(exc, UsageError):
        return f"{text.split(': ', 1)[0]}: error: {text.split(': ', 1)[1]}"
    if is_user_error(exc):
        return f"pedas-study: error: {text or type(exc).__name__}"
    hint = "" if os.environ.get("PEDAS_STUDY_DEBUG") else " (PEDAS_STUDY_DEBUG=1 shows the traceback)"
    return f"pedas-study: error: internal error: {type(exc).__name__}{': ' + text if text else ''}{hint}"


def _silence_stdout() -> None:
    """Point stdout at the null device: the reader of a pipe stopped reading (``pedas-study participant list |
    head``), and Python's final flush of stdout must not fail again (the recipe of the `signal` module's docs)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # no real file descriptor (stdout replaced in-process)
        pass


def _interruptible() -> None:
    """Ctrl-C (SIGINT) stops the command even when the parent started it with SIGINT ignored or blocked: a shell
    script's background job ignores it, and a process started while a thread blocked it inherits the mask. The
    servers (`survey serve`, `live serve`, `drive replay --serve`) stop on it."""
    if threading.current_thread() is not threading.main_thread():
        return  # signal dispositions belong to the main thread (main() called in-process from a thread)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def main(argv: Sequence[str] | None = None) -> int:
    """Run `pedas-study` with `argv` (default: the process arguments); the exit code."""
    _interruptible()
    try:
        if os.environ.get(LOG_ENV):  # e.g. info: how long a command waited for a store another process held
            logging.basicConfig(level=os.environ[LOG_ENV].upper(), format="pedas-study: %(message)s", force=True)
        args = build_parser().parse_args(argv)
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handling below, not at interpreter exit
    except BrokenPipeError:
        _silence_stdout()
        return 0
    except KeyboardInterrupt:
        print("pedas-study: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one line for the user; the traceback on request
        if os.environ.get("PEDAS_STUDY_DEBUG"):
            traceback.print_exc()
        print(error_line(exc), file=sys.stderr)
        return 2 if is_user_error(exc) else 1
    return int(code or 0)
