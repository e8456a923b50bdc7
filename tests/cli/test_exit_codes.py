"""Exit codes through the real CLI process: every bad invocation (argparse's included) exits 2 with exactly one
line on stderr and nothing on stdout; the store is unchanged."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import PAPER_STUDY, REPO


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    """A directory with a paper-study store (participant P001), a plain file and a sub-directory."""
    from pedas_study.cli import main

    d = tmp_path_factory.mktemp("exit")
    assert main([f"--db={d / 's.duckdb'}", "init", "--study", str(PAPER_STUDY)]) == 0
    assert main([f"--db={d / 's.duckdb'}", "participant", "add", "P001"]) == 0
    (d / "afile.csv").write_text("")
    (d / "dir").mkdir()
    return d


# (arguments, the start of the one stderr line); {d} is the lab directory
BAD = [
    ([], "pedas-study: error: the following arguments are required: COMMAND (see `pedas-study --help`)"),
    (["no-such-command"], "pedas-study: error: argument COMMAND: invalid choice: 'no-such-command'"),
    (["participant", "list", "--bogus"], "pedas-study: error: unrecognized arguments: --bogus"),
    (["session", "advance"], "pedas-study session advance: error: the following arguments are required: ID, PHASE"),
    (["survey", "serve", "--port", "abc"], "pedas-study survey serve: error: argument --port: invalid int value"),
    (["export", "xls", "{d}/out"], "pedas-study export: error: argument format: invalid choice: 'xls'"),
    (["exclude", "P001", "--scope", "none"], "pedas-study exclude: error: argument --scope: invalid choice"),
    (["session", "advance", "P001", "familiarisation", "--at", "noon"], "pedas-study: error: bad time 'noon'"),
    (["participant", "add", "X1"], "pedas-study: error: bad participant id 'X1'"),
    (["session", "status", "P999"], "pedas-study: error: unknown participant P999"),
    (["drive", "import", "P001", "baseline", "{d}/missing.csv"], "pedas-study: error: no such file"),
    (["survey", "import", "{d}/afile.csv"], "pedas-study: error: {d}/afile.csv: empty file"),
    (["export", "csv", "{d}/afile.csv"], "pedas-study: error: {d}/afile.csv exists and is not a directory"),
    (["survey", "final", "--out", "{d}/dir"], "pedas-study: error: [Errno 21] Is a directory"),
    (["kpi", "energy", "--trace", "{d}/missing.csv"], "pedas-study: error: trace file not found"),
    (["--db", "{d}/dir", "participant", "list"], "pedas-study: error: cannot open store {d}/dir"),
    (["--db", "{d}/typo.duckdb", "participant", "list"], "pedas-study: error: no store at {d}/typo.duckdb"),
]


def _counts(db: Path) -> dict[str, int]:
    from study.store.store import Store

    with Store.open(db, read_only=True) as st:
        return st.counts()


@pytest.mark.parametrize("args,start", BAD, ids=[" ".join(a) or "(none)" for a, _ in BAD])
def test_bad_invocation_exits_2_with_one_line(lab, args, start):
    before = _counts(lab / "s.duckdb")
    argv = [a.format(d=lab) for a in args]
    if not any(a.startswith("--db") for a in argv):
        argv = ["--db", str(lab / "s.duckdb")] + argv
    p = subprocess.run([sys.executable, "-m", "pedas_study.cli", *argv], capture_output=True, text=True,
                       cwd=REPO, timeout=120)
    assert p.returncode == 2, p.stderr
    assert p.stdout == ""
    assert p.stderr.endswith("\n") and p.stderr.count("\n") == 1, p.stderr
    assert p.stderr.startswith(start.format(d=lab)), p.stderr
    assert _counts(lab / "s.duckdb") == before
    assert not (lab / "typo.duckdb").exists()


def test_help_still_exits_0_with_the_usage(lab):
    p = subprocess.run([sys.executable, "-m", "pedas_study.cli", "session", "advance", "--help"],
                       capture_output=True, text=True, cwd=REPO, timeout=120)
    assert p.returncode == 0 and p.stdout.startswith("usage: pedas-study session advance ") and p.stderr == ""
