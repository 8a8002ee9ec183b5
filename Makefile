# voxwarp — quick start: `make run` and `make test` (each sets everything up on first use).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-dev
# pytest-xdist: one worker per core, each test file in one worker (its module fixtures and
# GL context stay together); PYTEST_WORKERS= runs the suite in one process
PYTEST_WORKERS ?= -n auto --dist loadfile
BENCH_STAMP := $(VENV)/.installed-bench

.PHONY: setup run test test-fast lint docs format bench clean

$(STAMP): pyproject.toml scripts/install-system-deps.sh
	@bash scripts/install-system-deps.sh
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "voxwarp needs Python >= 3.11; set PYTHON=python3.11"'
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[all,dev]'
	@touch $(STAMP)

setup: $(STAMP)

## open the desktop window on the bundled CT; without a display, render it headless into out/ (every mode, bent by a mass-spring drag and by a wire)
run: $(STAMP)
	$(VENV)/bin/voxwarp gui

## lint + the documentation site + the whole test suite, headless (GL tests fail, not skip,
## without an EGL context; the teaching notebooks are executed, the napari manifest validated)
test: $(STAMP) lint docs
	VOXWARP_REQUIRE_GL=1 $(PY) -m pytest $(PYTEST_WORKERS)

## the suite without the tests marked slow or load (a quick check while working; CI runs `make test`)
test-fast: $(STAMP)
	VOXWARP_REQUIRE_GL=1 $(PY) -m pytest $(PYTEST_WORKERS) -m "not slow and not load"

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) scripts/lint_imports.py
	$(PY) scripts/import_cycles.py

## the documentation site into site/ (warnings are errors); `mkdocs serve` to browse it
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --quiet -d site

format: $(STAMP)
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

$(BENCH_STAMP): $(STAMP)
	$(PY) -m pip install -q -e '.[all,dev,bench]'
	@touch $(BENCH_STAMP)

## the lab (benchmarks/, in the checkout, not installed): every benchmark, the hardware and one
## table (out/bench-all.md, .json); BENCH_ARGS=--quick for a few minutes; one: python -m benchmarks NAME
BENCH_ARGS ?=
bench: $(BENCH_STAMP)
	@mkdir -p out
	$(PY) -m benchmarks all $(BENCH_ARGS) --json out/bench-all.json --markdown out/bench-all.md

clean:
	rm -rf out site .pytest_cache tests/_failures
