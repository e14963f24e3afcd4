# Every command a person types. The environment is built from nothing in .venv.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
EXTRAS := .[plots,ros,dask,filterpy,stonesoup,fast,docs,dev]
# the tested versions (requirements/constraints.txt); `make lock` refreshes them
LOCK   := requirements/constraints.txt

.PHONY: install demo test fuzz docs test-oldest lock lint format bench bench-elt bench-versus outputs bench-dask sample-data config clean

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '$(EXTRAS)'
	$(BIN)/python -m compileall -q credcli  # as pip does for an installed package; see bench.py
	touch $(STAMP)

install: $(STAMP)

## lock: the newest release of every dependency, tested, written to requirements/constraints.txt
lock:
	rm -rf .venv-lock
	$(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet -e '$(EXTRAS)'
	.venv-lock/bin/python -m pytest -p no:cacheprovider -n auto
	{ sed -n '1,2p' $(LOCK); .venv-lock/bin/python -m pip freeze --exclude-editable \
	  | grep -v '^credcli'; } > $(LOCK).new && mv $(LOCK).new $(LOCK)
	rm -rf .venv-lock

## test-oldest: the test suite with the oldest versions pyproject.toml admits
test-oldest:
	rm -rf .venv-oldest
	$(PYTHON) -m venv .venv-oldest
	.venv-oldest/bin/python -m pip install --quiet --upgrade pip
	.venv-oldest/bin/python -m pip install --quiet -c requirements/oldest.txt -e '$(EXTRAS)'
	.venv-oldest/bin/python -m pytest -p no:cacheprovider -n auto

## demo: install, then diagnose the bundled sample log
demo: $(STAMP)
	$(BIN)/credcli diagnose sample_data/estimator_log.csv

## test: install, then run the whole test suite (on every core: pytest-xdist)
test: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist worksteal  # long tests do not wait behind a queue

## fuzz: the property tests with fresh random examples (make test draws each from a seed
## fixed by the test's source); run it as often as you like, and keep what it finds as an
## @example beside the test
fuzz: $(STAMP)
	HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -n auto -m property

lint: $(STAMP)
	$(BIN)/ruff check credcli tests
	$(BIN)/ruff format --check credcli tests

format: $(STAMP)
	$(BIN)/ruff format credcli tests
	$(BIN)/ruff check --fix credcli tests

## bench: measured wall time and peak memory of the main jobs (not a test)
bench: $(STAMP)
	$(BIN)/python benchmarks/bench.py
	$(BIN)/python benchmarks/speed.py
	$(BIN)/python benchmarks/calibrated_rule.py
	$(BIN)/python benchmarks/filters.py
	$(BIN)/python benchmarks/libraries.py
	$(BIN)/python benchmarks/heldout_filters.py
	$(BIN)/python benchmarks/cv_kf_600.py
	$(BIN)/python benchmarks/memory.py --quick
	$(BIN)/python benchmarks/memory.py --quick --windows 13 --lengths 50,300
	$(BIN)/python benchmarks/kf_variants.py
	$(BIN)/python benchmarks/variants.py
	$(BIN)/python benchmarks/se3.py
	$(BIN)/python benchmarks/findings.py
	$(BIN)/python benchmarks/frame.py
	$(BIN)/python benchmarks/dimensions.py

## bench-elt: the ELT's pair-matrix pass before (ELT_BASE) and after, interleaved (issue 35)
ELT_BASE ?= 2ee3e12
bench-elt: $(STAMP)
	rm -rf /tmp/credcli-elt-base && mkdir -p /tmp/credcli-elt-base
	git archive $(ELT_BASE) credcli | tar -x -C /tmp/credcli-elt-base
	$(BIN)/python benchmarks/elt_kernel.py /tmp/credcli-elt-base

## bench-versus: diagnose's wall, CPU and memory at BASE and here, interleaved (issue 35)
BASE ?= 579f626
bench-versus: $(STAMP)
	rm -rf /tmp/credcli-versus-base && mkdir -p /tmp/credcli-versus-base
	git archive $(BASE) credcli | tar -x -C /tmp/credcli-versus-base
	$(BIN)/python benchmarks/versus.py /tmp/credcli-versus-base $(if $(ONLY),--only '$(ONLY)')

## outputs: every kind of command's output at BASE and here, compared byte for byte (and,
## for JSON, label by label and key by key): the check of a change that claims none
outputs: $(STAMP)
	rm -rf /tmp/credcli-outputs && mkdir -p /tmp/credcli-outputs/base
	git archive $(BASE) credcli | tar -x -C /tmp/credcli-outputs/base
	$(BIN)/python benchmarks/outputs.py write /tmp/credcli-outputs/base /tmp/credcli-outputs/old
	$(BIN)/python benchmarks/outputs.py write . /tmp/credcli-outputs/new
	$(BIN)/python benchmarks/outputs.py compare /tmp/credcli-outputs/old /tmp/credcli-outputs/new

## bench-dask: only the Dask rows of make bench (issue 13)
bench-dask: $(STAMP)
	$(BIN)/python benchmarks/bench.py dask

## sample-data: regenerate sample_data/ from the generators in credcli/studies/samples.py
sample-data: $(STAMP)
	$(BIN)/python -m credcli.studies.samples sample_data

## config: regenerate configs/default.toml from the settings classes
## docs: the site from docs/ and the docstrings (site/), failing on any warning
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

config: $(STAMP)
	$(BIN)/python -m credcli.cli.settings > configs/default.toml

clean:
	rm -rf $(VENV) .venv-lock .venv-oldest .pytest_cache .ruff_cache *.egg-info
