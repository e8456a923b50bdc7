"""Shared fixtures: a temporary store, a CLI runner (in-process and as a subprocess) and a signed-in client of the
researcher console."""
from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

import pedas  # noqa: F401  (before anything imports numpy: the same SIMD paths as the CLI, see pedas/__init__.py)

REPO = Path(__file__).resolve().parents[1]
PAPER_STUDY = REPO / "studies" / "pedas_paper"
LK_STUDY = REPO / "studies" / "lane_keeping"
OUTPUT = REPO / "tests" / "output"  # screenshots and other artefacts a person may want to look at
CHROMIUM = Path(os.environ.get("PEDAS_CHROMIUM", "/usr/bin/chromium"))
# the browser tests: under CI a missing browser fails them instead of skipping them (.ci/run installs it)
needs_chromium = pytest.mark.skipif(not CHROMIUM.exists() and not os.environ.get("CI"),
                                    reason="needs Debian's chromium at /usr/bin/chromium (apt-get install chromium)")


@dataclass
class CliResult:
    code: int
    out: str
    err: str


@pytest.fixture
def tmp_db(tmp_path) -> Path:
    """Path of a fresh (not yet initialised) store."""
    return tmp_path / "study.duckdb"


_INITIALISED: dict[Path, Path] = {}


def initialised_store(tmp_db: Path, study: Path, tmp_path_factory) -> Path:
    """`tmp_db` as `pedas-study init --study <study>` leaves it: a copy of a store initialised once per test process
    (init takes ~0.25 s, a copy of the closed file ~2 ms; the store keeps no path of its own)."""
    import shutil

    from pedas_study.cli import main

    if study not in _INITIALISED:
        template = tmp_path_factory.mktemp("initialised") / "study.duckdb"
        assert main([f"--db={template}", "init", "--study", str(study)]) == 0
        _INITIALISED[study] = template
    shutil.copyfile(_INITIALISED[study], tmp_db)
    return tmp_db


@pytest.fixture
def paper_db(tmp_db, tmp_path_factory) -> Path:
    """A fresh store serving the paper's study (studies/pedas_paper)."""
    return initialised_store(tmp_db, PAPER_STUDY, tmp_path_factory)


@pytest.fixture
def lk_db(tmp_db, tmp_path_factory) -> Path:
    """A fresh store serving the lane-keeping example study (studies/lane_keeping)."""
    return initialised_store(tmp_db, LK_STUDY, tmp_path_factory)


@pytest.fixture(autouse=True)
def _one_parser_per_test(monkeypatch):
    """`main()` builds the whole parser for every call (~25 ms, most of it argparse looking up translations); the
    in-process calls of one test share the parser its first call builds, after any handler the test patched."""
    import pedas_study.cli as entry

    build, built = entry.build_parser, []

    def once():
        if not built:
            built.append(build())
        return built[0]

    monkeypatch.setattr(entry, "build_parser", once)


@pytest.fixture
def cli(tmp_db, capsys):
    """Run `pedas-study --db tmp_db ARGS...` in-process; returns CliResult(code, out, err)."""
    from pedas_study.cli import main

    def run(*args: str, db: Path | None = tmp_db) -> CliResult:
        argv = ([f"--db={db}"] if db is not None else []) + [str(a) for a in args]
        capsys.readouterr()
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse usage errors
            code = exc.code if isinstance(exc.code, int) else 2
        cap = capsys.readouterr()
        return CliResult(code, cap.out, cap.err)

    return run


@pytest.fixture
def cli_proc(tmp_db):
    """Run `pedas-study --db tmp_db ARGS...` as a separate process (for kill/concurrency tests)."""
    def run(*args: str, db: Path | None = tmp_db, timeout: float = 600, **kw) -> CliResult:
        argv = [sys.executable, "-m", "pedas_study.cli"] + ([f"--db={db}"] if db is not None else []) \
            + [str(a) for a in args]
        env = {**os.environ, **kw.pop("env", {})}
        p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, env=env, cwd=REPO, **kw)
        return CliResult(p.returncode, p.stdout, p.stderr)

    return run


@pytest.fixture
def console_store(paper_db):
    """The store of the researcher console's tests: the paper's study (actor lab) with participants P001 and P002. A
    test module whose console serves another store overrides this fixture."""
    from study.people.participants import add_participant
    from study.store.store import Store

    st = Store.open(paper_db, actor="lab")
    for pid in ("P001", "P002"):
        add_participant(st, pid)
    yield st
    st.close()


@pytest.fixture
def console_app(console_store):
    """The web app on `console_store` with the researcher password of the web tests (tests/study/test_survey_web.py).
    A test module that needs other settings (sign-in) overrides this fixture."""
    from study.webapp import create_app
    from tests.study.test_survey_web import PASSWORD

    return create_app(console_store, PASSWORD)


@pytest.fixture
def console_client(console_app):
    """A test client of `console_app` with the researcher signed in; ``.csrf`` is the session's CSRF token."""
    from tests.study.test_survey_web import login

    c = console_app.test_client()
    c.csrf = login(c)
    return c


@pytest.fixture(scope="module")
def browser():
    """Debian's headless Chromium through Playwright (pedas.hud_png.launch: the HUD figures' browser settings)."""
    from playwright.sync_api import sync_playwright

    from pedas.hud_png import launch

    with sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


def python_under_kernel(coretype: str, code: str) -> str:
    """stdout of `code` run by this Python in a fresh process with OpenBLAS forced to kernel `coretype`."""
    env = {**os.environ, "OPENBLAS_CORETYPE": coretype, "PYTHONPATH": str(REPO)}
    p = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout


def needs_r(*packages: str):
    """Skip unless Rscript and every R package in `packages` are installed (the R cross-checks rerun the committed
    R scripts; CI does not install R, the committed fixtures are what the other tests compare with)."""
    import shutil

    if shutil.which("Rscript") is None:
        return pytest.mark.skipif(True, reason="R (Rscript) is not installed")
    probe = "quit(status = !all(sapply(c(%s), requireNamespace, quietly = TRUE)))" % ", ".join(f'"{p}"' for p in packages)
    ok = subprocess.run(["Rscript", "-e", probe], capture_output=True).returncode == 0
    return pytest.mark.skipif(not ok, reason=f"R packages {', '.join(packages)} are not all installed")
