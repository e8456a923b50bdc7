"""The same seed gives the same drive log, byte for byte, whatever BLAS/LAPACK kernel numpy picks at run time.

Each kernel runs in its own subprocess (OpenBLAS reads OPENBLAS_CORETYPE once, at load). The subprocess prints
the kernel it actually got (threadpoolctl), every fitted model parameter (refitted, not read from the committed
file) and writes a baseline and a pEDAS drive log with full float precision.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = r"""
import json, sys
from threadpoolctl import threadpool_info
from pedas.fitted import refit
from pedas.drive import drive
out = sys.argv[1]
arch = sorted({i.get("architecture") for i in threadpool_info() if i.get("internal_api") == "openblas"})
for cond in ("baseline", "pedas"):
    drive(2024, "normal", cond).to_csv(f"{out}/{cond}.csv", index=False, float_format="%.17g")
print(json.dumps({"arch": arch, "fits": refit()}))
"""


def _kernels() -> list[str]:
    kernels = ["Prescott", "Haswell"]
    cpu = Path("/proc/cpuinfo")
    if cpu.exists() and " avx512f" in cpu.read_text():
        kernels.append("SkylakeX")
    return kernels


def _run(kernel: str, out: Path) -> subprocess.Popen:
    out.mkdir()
    env = {**os.environ, "OPENBLAS_CORETYPE": kernel}
    return subprocess.Popen([sys.executable, "-c", SCRIPT, str(out)], cwd=REPO, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


@pytest.mark.sumo
@pytest.mark.slow
def test_drive_logs_and_fits_are_identical_under_every_kernel(tmp_path):
    kernels = _kernels()
    procs = {k: _run(k, tmp_path / k) for k in kernels}
    res = {}
    for k, p in procs.items():
        out, err = p.communicate(timeout=900)
        assert p.returncode == 0, err[-2000:]
        res[k] = json.loads(out.strip().splitlines()[-1])
    # the test can only fail if the kernels really differ
    assert len({tuple(r["arch"]) for r in res.values()}) == len(kernels), res
    ref = kernels[0]
    for k in kernels[1:]:
        assert res[k]["fits"] == res[ref]["fits"], k
        for cond in ("baseline", "pedas"):
            a = (tmp_path / ref / f"{cond}.csv").read_bytes()
            b = (tmp_path / k / f"{cond}.csv").read_bytes()
            assert len(a) > 100_000 and a == b, f"{cond} drive differs between {ref} and {k}"


SURVEY_SCRIPT = r"""
import sys
from analysis.survey.acceptance import analyze_survey
from analysis.paper.published import paper_study
from pedas.paths import REFERENCE_DIR
import pandas as pd
responses = pd.read_csv(REFERENCE_DIR / "survey.csv")
analyze_survey(responses, paper_study()).write(sys.argv[1])
"""


@pytest.mark.slow
def test_survey_regressions_are_identical_under_every_kernel(tmp_path):
    """The hierarchical regressions (and their bootstrap CIs) of the reference survey, written by `write`, are
    the same bytes under every kernel: their normal equations are solved without BLAS."""
    kernels = _kernels()
    procs = {}
    for k in kernels:
        env = {**os.environ, "OPENBLAS_CORETYPE": k}
        procs[k] = subprocess.Popen([sys.executable, "-c", SURVEY_SCRIPT, str(tmp_path / k)], cwd=REPO, env=env,
                                    text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    for k, p in procs.items():
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err[-2000:]
    for name in ("regressions.csv", "hypotheses.csv"):
        ref = (tmp_path / kernels[0] / name).read_bytes()
        for k in kernels[1:]:
            assert (tmp_path / k / name).read_bytes() == ref, f"{name} differs between {kernels[0]} and {k}"
