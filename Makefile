# Every target sets up .venv by itself: python3 -m venv, the exact versions of requirements.lock, then the project
# itself (editable, no second resolution; this builds the compiled kernel pedas/_qpkernel.c with the machine's C
# compiler, and an edit of that file builds it again). `make lock` regenerates the lock from pyproject.toml's ranges.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
LOCK   := requirements.lock
OUT    ?= reports
PYTEST_ARGS ?=
# numpy on its AVX2 code paths on every x86-64 CPU: the same float64 results with and without AVX-512
# (importing pedas sets the same default; here it also holds for anything that imports numpy first)
export NPY_DISABLE_CPU_FEATURES ?= X86_V4 AVX512_ICL AVX512_SPR
# the locking tool's version, and extra options for it, e.g. LOCK_ARGS=--upgrade or LOCK_ARGS='--upgrade-package numpy'
UV_VERSION ?= 0.13.9
LOCK_ARGS ?=

.DEFAULT_GOAL := report
.PHONY: report test test-quick bench serve clean venv lock refit sweep

# uv installs the lock in parallel (a fresh 2-core machine: ~30 s against pip's ~90 s), .pyc files included as pip
# writes them; where uv cannot install (no index it can reach), pip installs the same hashed lock
UV_INSTALL = $(BIN)/uv pip install -q --python $(BIN)/python --compile-bytecode

$(STAMP): pyproject.toml $(LOCK) pedas/_qpkernel.c pedas/_daqp_abi.h
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q uv==$(UV_VERSION)
	$(UV_INSTALL) --require-hashes -r $(LOCK) || $(BIN)/python -m pip install -q --require-hashes -r $(LOCK)
	$(UV_INSTALL) --no-deps -e . || $(BIN)/python -m pip install -q --no-deps -e .
	touch $(STAMP)

# CPython 3.11 on x86-64 Linux, the runtime dependencies plus every extra (test, bench, dask), every file's sha256
lock:
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q uv==$(UV_VERSION)
	$(BIN)/uv pip compile pyproject.toml --all-extras --python-version 3.11 --python-platform x86_64-unknown-linux-gnu \
		--generate-hashes --custom-compile-command 'make lock' --quiet $(LOCK_ARGS) -o $(LOCK)

venv: $(STAMP)

# refit the vehicle model's committed coefficients (pedas/fitted_coefficients.json; exact, machine-independent)
refit: $(STAMP)
	$(BIN)/python -m pedas.fitted

# the report builds data/study.duckdb itself for the paper's study (as `pedas-study init --study studies/pedas_paper`),
# loads data/reference/ and simulates the drives; reports/index.html is the report as one document (docs/report.md)
report: $(STAMP)
	$(PYC)
	$(BIN)/pedas-study report --out $(OUT)

# the what-if sweep (docs/sweep.md): the default design, ~30 min on 2 cores, resumable (every drive is cached); its
# data (design.csv, points.csv, sweep.json) go to data/sweep/, which `make report` re-analyses without simulating.
# SWEEP_ARGS adds options, e.g. SWEEP_ARGS='--scheduler tcp://host:8786'
SWEEP_OUT ?= .report-cache/sweep-out
SWEEP_ARGS ?=
sweep: $(STAMP)
	$(BIN)/pedas-study simulate sweep --out $(SWEEP_OUT) $(SWEEP_ARGS)
	mkdir -p data/sweep
	cp $(SWEEP_OUT)/design.csv $(SWEEP_OUT)/points.csv $(SWEEP_OUT)/sweep.json data/sweep/

# the project's modules compiled once: where PYTHONDONTWRITEBYTECODE is set, every command the tests, benches and
# the report start (the report's drive workers too) would compile them again (~0.1 s each, ~0.4 s for drive import)
PYC = $(BIN)/python -m compileall -q pedas study analysis pedas_study

test: $(STAMP)
	$(PYC)
	$(BIN)/python -m pytest -n 2 --dist loadgroup $(PYTEST_ARGS)

# the development loop: the suite without its long end-to-end tests (markers slow, sumo, browser)
test-quick: $(STAMP)
	$(PYC)
	$(BIN)/python -m pytest -n 2 --dist loadgroup -m "not slow and not sumo and not browser" $(PYTEST_ARGS)

bench: $(STAMP)
	$(PYC)
	$(BIN)/pedas-study bench cli
	$(BIN)/pedas-study bench mpc
	$(BIN)/pedas-study bench drive
	$(BIN)/pedas-study bench kpi
	$(BIN)/pedas-study bench import
	$(BIN)/pedas-study bench export
	$(BIN)/pedas-study bench survey

serve: $(STAMP)
	$(BIN)/pedas-study survey serve

clean:
	rm -f pedas/_qpkernel.*.so
	rm -rf $(VENV) reports data/study.duckdb data/study.duckdb.wal data/network/build .pytest_cache .report-cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
