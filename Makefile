# Quick start: `make demo` solves the default built-in scenario, `make test` runs the test suite.
# Only python3, make and a Rust toolchain (cargo) are assumed; everything else is installed into
# .venv by these targets. The first install compiles the solver core (rust/): about two minutes.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
CARGO ?= cargo
RUST_SOURCES := $(shell find rust -name '*.rs' -o -name 'Cargo.toml' -o -name 'Cargo.lock')

.PHONY: demo test test-rust lint typecheck check bench bench-nets clean gallery

$(STAMP): pyproject.toml $(RUST_SOURCES)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	@echo "installing funicular and compiling its solver core (about two minutes the first time)"
	$(BIN)/python -m pip install --quiet -e '.[plot,test,dev,expr,progress,parquet,cluster,ipopt,bench,serve]'
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/funicular solve two-supports --plot out/two-supports.png --json out/two-supports.json

test: $(STAMP) test-rust
	bash scripts/ensure_chromium.sh
	$(BIN)/python -m pytest -q

# The core's own unit tests (linear algebra, derivatives, the iteration on small chains).
test-rust:
	$(CARGO) test --quiet --manifest-path rust/Cargo.toml -p funicular-core --lib --tests

lint: $(STAMP)
	$(BIN)/ruff check src tests bench
	$(BIN)/ruff format --check src tests bench
	$(CARGO) fmt --manifest-path rust/Cargo.toml --all --check
	$(CARGO) clippy --quiet --manifest-path rust/Cargo.toml --all-targets -- -D warnings

typecheck: $(STAMP)
	$(BIN)/mypy

check: lint typecheck test

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache rust/target

# funicular against IPOPT, Clarabel and SLSQP for N = 50 to 100,000 (each competitor up to the N where it
# is practical). The million-node case (docs/benchmark-1e6.md):
# $(BIN)/python bench/run.py --nodes 1000000 --solvers funicular --repeats 5 --markdown docs/benchmark-1e6.md [--profile]
# (BLAS single-threaded for every solver: docs/performance.md says why)
bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python bench/run.py --markdown docs/benchmark.md --plot docs/benchmark.png
	$(BIN)/python bench/explorer.py --markdown docs/explorer-latency.md

# funicular against Clarabel and IPOPT on n x n cable nets, free and over a sphere (about 25 minutes on 2 cores)
bench-nets: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python bench/nets.py --markdown docs/benchmark-nets.md --plot docs/benchmark-nets.png

gallery: $(STAMP)
	$(BIN)/python scripts/gallery.py

# The documentation site (mkdocs-material, mkdocstrings) into site/; builds offline. The docs extra
# is installed into .venv once (not `pip install -e '.[docs]'`, which would compile the core again).
DOCS_STAMP := $(VENV)/.docs-installed
.PHONY: docs
# Needs the installed package, but does not reinstall it when pyproject.toml is newer than .venv.
$(DOCS_STAMP): | $(if $(wildcard $(STAMP)),,$(STAMP))
	$(BIN)/python -m pip install --quiet 'mkdocs-material>=9' 'mkdocstrings[python]>=0.25'
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site
