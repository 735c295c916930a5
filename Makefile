# woundsweep: `make demo` runs the pipeline on sweeps/demo.yaml; `make test` runs the tests.
# Both call `make setup` first (idempotent: a second run does nothing slow); `make test` then
# `make test-deps` (the system packages of the tests marked `system`; idempotent too).
VENV    := .venv
PY      := $(VENV)/bin/python
WS      := $(VENV)/bin/woundsweep
DEMO_DIR ?= runs/demo
PYTEST_ARGS ?=

.PHONY: setup test-deps test test-fast test-dolfinx-latest verify demo chart chart-code atlas-page models bench bench-convergence bench-scale lint format clean

setup:
	@bash scripts/setup.sh

# Debian's slurm-wlm, munge, chromium and chromium-driver, for the tests marked `system`
# (without them pytest skips those tests, naming this target).
test-deps:
	@bash scripts/test-deps.sh

# One pytest worker per core (pytest-xdist), each taking whole test files so that a file's
# fixtures are built once; PYTEST_WORKERS=0 runs in one process.
PYTEST_WORKERS ?= auto
test: setup test-deps
	$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=25 $(PYTEST_ARGS)

# Tests that do not need DOLFINx (seconds).
test-fast: setup
	$(PY) -m pytest -q -m "not fem and not slow" $(PYTEST_ARGS)

# The fem tests + one demo job on DOLFINx 0.11 (Debian sid, cached debootstrap root under
# /var/cache/woundsweep, ~3 min and 3.5 GB on first use; needs root), compared with 0.5.2.
test-dolfinx-latest: setup
	bash scripts/dolfinx-latest.sh $(if $(PYTEST_ARGS),-- $(PYTEST_ARGS))

# The verification cases (docs/validation.md, "Verification"): VERIFY_ARGS=--quick is CI's
# minute-scale subset; without it the full set (a few minutes on two cores).
VERIFY_ARGS ?=
verify: setup
	$(WS) verify $(VERIFY_ARGS)

DEMO_STAGES ?= 1-6
DEMO_FIELDS ?= all

demo: setup
	$(WS) generate sweeps/demo.yaml --out $(DEMO_DIR)
	$(WS) run $(DEMO_DIR) --stages $(DEMO_STAGES) --fields $(DEMO_FIELDS)
	$(WS) status $(DEMO_DIR)
	$(WS) analyze $(DEMO_DIR)
	@echo "demo: results in $(DEMO_DIR)/results (pandas.read_parquet), fields in $(DEMO_DIR)/fields,"
	@echo "      analysis in $(DEMO_DIR)/analysis (report.md, metrics.json, figures)"
	$(WS) atlas $(DEMO_DIR) --out $(DEMO_DIR)/atlas
	@echo "demo: atlas index: $(abspath $(DEMO_DIR))/atlas/index.html (open it in a browser)"

# The paper grid charted in parts (docs/atlas.md): continues from the kept table
# charted/paper.parquet, runs the shards it lacks for CHART_HOURS, packs every 15 minutes and when stopped.
CHART_SWEEP ?= sweeps/paper.yaml
CHART_TABLE ?= charted/paper.parquet
CHART_RUN ?= runs/chart-paper
CHART_HOURS ?= 1
CHART_SHARDS ?= 486
chart: setup
	$(PY) scripts/chart.py --sweep $(CHART_SWEEP) --table $(CHART_TABLE) --run $(CHART_RUN) \
	    --shards $(CHART_SHARDS) --hours $(CHART_HOURS)

# The published code's closure on every wound of the grid once (sweeps/paper-code-slice.yaml:
# t_d = 1 mm, mesh factor 0.5; 972 jobs in 41 shards), kept in charted/paper-code-slice.parquet.
chart-code:
	$(MAKE) chart CHART_SWEEP=sweeps/paper-code-slice.yaml CHART_TABLE=charted/paper-code-slice.parquet \
	    CHART_RUN=runs/chart-paper-code-slice CHART_SHARDS=41

# docs/atlas.md and docs/figures/atlas/ written anew from the kept tables (scripts/atlas_build.py):
# a run of each sweep with its table unpacked (in ATLAS_DIR, replaced), `analyze` of the paper
# run with the GP surrogate, its intervals calibrated on ATLAS_CAL pooled and tested on
# ATLAS_TEST, Figure 2 beside that of each ATLAS_BESIDE run (paper jobs under another closing
# load: the paper-code slice once charted/paper-code-slice.parquet exists), `status` and
# `atlas` on it, each timed for the page (minutes).
ATLAS_DIR ?= runs/atlas-page
ATLAS_CAL ?= paper-random-1 paper-random-2
ATLAS_TEST ?= paper-between-calibration paper-between-test
ATLAS_BESIDE ?= $(if $(wildcard charted/paper-code-slice.parquet),paper-code-slice)
atlas-page: setup
	$(PY) scripts/atlas_build.py --dir $(ATLAS_DIR) $(foreach c,$(ATLAS_CAL),--cal $(c)) \
	    $(foreach t,$(ATLAS_TEST),--test $(t)) $(foreach b,$(ATLAS_BESIDE),--beside $(b))

# The models shipped with woundsweep (woundsweep/models/, what `predict` answers with when no
# model is given): analyze on the charted table, the intervals calibrated on the off-grid
# tables charted/NAME.parquet of sweeps/NAME.yaml for each NAME in MODELS_CAL, pooled, their
# coverage estimated by cross-calibration (docs/model.md, "The surrogate's intervals";
# MODELS_CAL= skips the calibration off the grid), MODELS_ARGS passed on to analyze: the
# Gaussian-process surrogate, the one that holds between the grid's values (docs/atlas.md),
# and the classifier of the geometry split only (the one for new wounds; the random split's
# doubles the size).
MODELS_TABLE ?= charted/paper.parquet
MODELS_SWEEP ?= sweeps/paper.yaml
MODELS_CAL ?= paper-random-1 paper-random-2
MODELS_ARGS ?= --param surrogate=gp --split geometry
models: setup
	$(PY) scripts/ship_models.py --table $(MODELS_TABLE) --sweep $(MODELS_SWEEP) \
	    $(foreach c,$(MODELS_CAL),--calibrate-on-table charted/$(c).parquet --calibrate-sweep sweeps/$(c).yaml) \
	    $(MODELS_ARGS)

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

# p99's mesh convergence on the paper geometries of benchmarks/convergence.py at six mesh
# size factors, two jobs at once (not part of bench: about ten minutes on two cores).
bench-convergence: setup
	$(WS) generate sweeps/paper.yaml --out runs/paper
	$(PY) benchmarks/convergence.py runs/paper --workers 2

# status, analyze, atlas and export timed on the paper grid filled with 11,664 synthetic
# results (not part of bench: about 30 minutes on two cores); SCALE_ARGS=--jobs 500 is a
# quick check on a sub-grid.
SCALE_ARGS ?=
bench-scale: setup
	$(PY) benchmarks/scale.py $(SCALE_ARGS)

lint: setup
	$(VENV)/bin/ruff check woundsweep tests benchmarks
	$(VENV)/bin/ruff format --check woundsweep tests benchmarks
	$(VENV)/bin/mypy

format: setup
	$(VENV)/bin/ruff format woundsweep tests benchmarks
	$(VENV)/bin/ruff check --fix woundsweep tests benchmarks

clean:
	rm -rf runs .pytest_cache .ruff_cache
