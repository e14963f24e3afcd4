# Every command a person types. The environment is built from nothing in .venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: install demo test lint format bench bench-dask sample-data clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[plots,ros,dask,dev]'
	$(BIN)/python -m compileall -q credcli  # as pip does for an installed package; see bench.py
	touch $(STAMP)

install: $(STAMP)

## demo: install, then diagnose the bundled sample log
demo: $(STAMP)
	$(BIN)/credcli diagnose sample_data/estimator_log.csv

## test: install, then run the whole test suite
test: $(STAMP)
	$(BIN)/python -m pytest

lint: $(STAMP)
	$(BIN)/ruff check credcli tests
	$(BIN)/ruff format --check credcli tests

format: $(STAMP)
	$(BIN)/ruff format credcli tests
	$(BIN)/ruff check --fix credcli tests

## bench: measured wall time and peak memory of the main jobs (not a test)
bench: $(STAMP)
	$(BIN)/python benchmarks/bench.py
	$(BIN)/python benchmarks/calibrated_rule.py

## bench-dask: only the Dask rows of make bench (issue 13)
bench-dask: $(STAMP)
	$(BIN)/python benchmarks/bench.py dask

## sample-data: regenerate sample_data/ from the generators in credcli/studies/samples.py
sample-data: $(STAMP)
	$(BIN)/python -m credcli.studies.samples sample_data

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache *.egg-info
