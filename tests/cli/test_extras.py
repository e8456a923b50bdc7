"""Optional dependencies (pyproject's extras): declared outside the runtime dependencies, imported lazily, and a
missing one fails with one line naming the extra."""
from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

import pytest

from pedas_study.extras import require
from study.common.errors import UserError

REPO = Path(__file__).resolve().parents[2]
OPTIONAL = {"cvxpy": "bench", "clarabel": "bench", "dask": "dask"}


def test_optional_packages_are_extras_not_runtime_dependencies():
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    runtime = {re.match(r"[A-Za-z0-9_.-]+", r).group(0).lower() for r in project["dependencies"]}
    extras = project["optional-dependencies"]
    for name, extra in OPTIONAL.items():
        assert name not in runtime
        assert any(r.startswith(name) for r in extras[extra]), (name, extra)
        assert any(r.startswith(name) for r in extras["test"]), name


@pytest.mark.parametrize("package", ["pedas", "study", "analysis", "pedas_study"])
def test_optional_and_heavy_packages_are_imported_lazily(package):
    # pingouin and statsmodels are runtime dependencies (within-subjects comparisons) but slow to import
    top_level = re.compile(r"^(?:from|import)\s+(pingouin|statsmodels|cvxpy|clarabel|dask|distributed)\b", re.M)
    found = [str(p.relative_to(REPO)) for p in (REPO / package).rglob("*.py") if top_level.search(p.read_text())]
    assert found == []


def test_require_names_the_extra():
    require("json", "bench", "anything")
    with pytest.raises(UserError, match=r"^bench mpc needs no_such_module_x: install pedas-study\[bench\]$"):
        require("no_such_module_x", "bench", "bench mpc")


def test_scheduler_without_dask_is_bad_input(cli, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    r = cli("simulate", "cohort", "--scheduler", "tcp://127.0.0.1:1", "--no-progress")
    assert r.code == 2
    assert r.err == "pedas-study: error: --scheduler needs distributed: install pedas-study[dask]\n"


def test_bench_mpc_without_cvxpy_is_bad_input(cli, monkeypatch):
    monkeypatch.setitem(sys.modules, "cvxpy", None)
    r = cli("bench", "mpc", "--steps", "5", "--peer-steps", "1", db=None)
    assert r.code == 2
    assert r.err == "pedas-study: error: the cvxpy peer of bench mpc needs cvxpy: install pedas-study[bench]\n"
