# Every target sets up .venv by itself (python3 -m venv + pip install -e .[test]).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
OUT    ?= reports
PYTEST_ARGS ?=

.DEFAULT_GOAL := report
.PHONY: report test bench serve clean venv

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

report: $(STAMP)
	$(BIN)/pedas-study report --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadgroup $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/pedas-study bench mpc
	$(BIN)/pedas-study bench drive
	$(BIN)/pedas-study bench kpi
	$(BIN)/pedas-study bench import
	$(BIN)/pedas-study bench survey

serve: $(STAMP)
	$(BIN)/pedas-study survey serve

clean:
	rm -rf $(VENV) reports data/study.duckdb data/study.duckdb.wal data/network/build .pytest_cache .report-cache
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
