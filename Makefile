# Quick start: `make demo` solves the default built-in scenario, `make test` runs the test suite.
# Only python3 and make are assumed; everything else is installed into .venv by these targets.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint typecheck check bench clean gallery

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[plot,test,dev,expr,progress,ipopt,bench,fast]'
	@echo "compiling numba's kernels once (about a minute on a fresh install)"
	$(BIN)/python -m funicular.solver.warm_up
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/funicular solve two-supports --plot out/two-supports.png --json out/two-supports.json

test: $(STAMP)
	bash scripts/ensure_chromium.sh
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check src tests
	$(BIN)/ruff format --check src tests

typecheck: $(STAMP)
	$(BIN)/mypy

check: lint typecheck test

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache

# funicular against IPOPT, Clarabel and SLSQP for N = 50 to 100,000 (each competitor up to the N where it
# is practical). The million-node case (docs/benchmark-1e6.md):
# $(BIN)/funicular bench --nodes 1000000 --solvers funicular --repeats 1 --markdown docs/benchmark-1e6.md [--profile]
bench: $(STAMP)
	$(BIN)/funicular bench --markdown docs/benchmark.md --plot docs/benchmark.png

gallery: $(STAMP)
	$(BIN)/python scripts/gallery.py
