# woundsweep: `make demo` runs the pipeline on sweeps/demo.yaml; `make test` runs the tests.
# Both call `make setup` first (idempotent: a second run does nothing slow).
VENV    := .venv
PY      := $(VENV)/bin/python
WS      := $(VENV)/bin/woundsweep
DEMO_DIR ?= runs/demo
PYTEST_ARGS ?=

.PHONY: setup test test-fast demo bench lint format clean

setup:
	@bash scripts/setup.sh

test: setup
	$(PY) -m pytest -q $(PYTEST_ARGS)

# Tests that do not need DOLFINx (seconds).
test-fast: setup
	$(PY) -m pytest -q -m "not fem and not slow" $(PYTEST_ARGS)

demo: setup
	$(WS) generate sweeps/demo.yaml --out $(DEMO_DIR)
	@echo "demo: manifest in $(DEMO_DIR)/manifest.parquet"

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

lint: setup
	$(VENV)/bin/ruff check woundsweep tests benchmarks
	$(VENV)/bin/ruff format --check woundsweep tests benchmarks

format: setup
	$(VENV)/bin/ruff format woundsweep tests benchmarks
	$(VENV)/bin/ruff check --fix woundsweep tests benchmarks

clean:
	rm -rf runs .pytest_cache .ruff_cache
