# Quick start: `make demo` solves the default built-in scenario, `make test` runs the test suite.
# Only python3, make and a Rust toolchain (cargo) are assumed; everything else is installed into
# .venv by these targets. The first install compiles the solver core (rust/): about two minutes.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
CARGO ?= cargo
RUST_SOURCES := $(shell find rust -path rust/target -prune -o \( -name '*.rs' -o -name 'Cargo.toml' -o -name 'Cargo.lock' \) -print)

.PHONY: demo test test-rust lint typecheck check bench bench-nets clean gallery wheel check-wheel

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
# $(BIN)/python -m bench.run --nodes 1000000 --solvers funicular --repeats 5 --markdown docs/benchmark-1e6.md [--profile]
# (BLAS single-threaded for every solver: docs/performance.md says why)
bench: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m bench.run --markdown docs/benchmark.md --plot docs/benchmark.png
	$(BIN)/python -m bench.explorer --markdown docs/explorer-latency.md

# funicular against Clarabel and IPOPT on n x n cable nets, free and over a sphere (about 25 minutes on 2 cores)
bench-nets: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m bench.nets --markdown docs/benchmark-nets.md --plot docs/benchmark-nets.png

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

# A binary wheel and an sdist in dist/, for installing funicular where there is no Rust toolchain
# (`pip install dist/funicular-*.whl`). maturin is pinned here and installed into .venv on its own, so
# building a wheel does not need the editable install. The wheel is built from the tree, not from the
# sdist: the sdist's files all carry one fixed date, so cargo would take a changed source in it for
# one older than a previous build and ship the stale core. It is built for the baseline x86-64 CPU:
# RUSTFLAGS names it, overriding any target-cpu in the environment or a cargo config, so the wheel
# runs on any x86-64 CPU (Intel or AMD). The manylinux tag is the oldest glibc that the compiled
# core's symbols allow when built on this machine's glibc 2.36 (hypot needs 2.35); maturin's
# auditwheel check refuses the build if that no longer holds. (`maturin sdist` is given the manifest
# that pyproject.toml names: without it, it first reports an error about a missing ./Cargo.toml.)
MATURIN_VERSION := 1.16.0
MANYLINUX := manylinux_2_35
MATURIN_STAMP := $(VENV)/.maturin-$(MATURIN_VERSION)
VERSION := $(shell sed -n 's/^version = "\(.*\)"$$/\1/p' pyproject.toml | head -n 1)
WHEEL := dist/funicular-$(VERSION)-cp311-abi3-$(MANYLINUX)_x86_64.whl
PACKAGE_SOURCES := $(shell find src -type f ! -name '*.so' ! -name '*.pyc') README.md

$(MATURIN_STAMP):
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet 'maturin==$(MATURIN_VERSION)'
	touch $@

$(WHEEL): Makefile $(MATURIN_STAMP) pyproject.toml $(RUST_SOURCES) $(PACKAGE_SOURCES)
	rm -f dist/funicular-*.whl dist/funicular-*.tar.gz
	env -u CARGO_ENCODED_RUSTFLAGS RUSTFLAGS='-C target-cpu=x86-64' \
		$(BIN)/maturin build --release --locked --strip --compatibility $(MANYLINUX) --out dist
	$(BIN)/maturin sdist --manifest-path rust/python/Cargo.toml --out dist
	@ls -l dist

wheel: $(WHEEL)

# Installs the wheel into a fresh virtual environment with no Rust toolchain on PATH and runs it.
check-wheel: $(WHEEL)
	PYTHON=$(PYTHON) bash scripts/check_wheel.sh $(WHEEL)
