# calstudy: `make reproduce` regenerates results/ and the book, `make test` proves it.
# Both create the virtual environment first (Python 3.11 with venv; pip must reach the package
# registry). `make help` lists the targets.

SHELL := bash
.SHELLFLAGS := -euo pipefail -c
.DEFAULT_GOAL := help
.DELETE_ON_ERROR:
MAKEFLAGS += --no-builtin-rules

# Reproducible bytes: no display, single-threaded BLAS, fixed hash seed. The kernel that
# papermill starts inherits these; the venv's own kernel spec comes first.
export MPLBACKEND := Agg
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1
export PYTHONHASHSEED := 0
export JUPYTER_PREFER_ENV_PATH := 1
export PYDEVD_DISABLE_FILE_VALIDATION := 1

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

NOTEBOOKS := $(sort $(wildcard notebooks/[0-9][0-9]_*.ipynb))
EXECUTED := $(patsubst notebooks/%.ipynb,book/notebooks/%.ipynb,$(NOTEBOOKS))
LIBRARY := $(sort $(shell find src/calstudy -name '*.py' -not -path '*/__pycache__/*'))
DATA := $(sort $(shell find data -type f -not -name '.*' -not -path '*/__pycache__/*' 2>/dev/null))
RESULTS := $(sort $(shell find results -mindepth 2 -type f -not -path '*/.*' 2>/dev/null))
BOOK_SOURCES := book/_config.yml book/_toc.yml book/references.bib \
	$(filter-out book/claims.md book/ledger.md,$(wildcard book/*.md)) book/claims.md book/ledger.md \
	$(wildcard book/_ext/*.py) $(wildcard book/_static/*)
BOOK_STAMP := book/_build/html/.built

.PHONY: help venv browser reproduce notebooks run-notebooks test check-book verify lint book bench clean FORCE

# What each notebook depends on: itself, its paper's package, the library modules these import
# and its data (calstudy.io.dependencies, the same list run.json's digest covers), as one rule
# a notebook in NOTEBOOK_RULES. The module needs the standard library only, so $(PYTHON) writes
# the rules before the venv exists; they are written again when a library, data or notebook
# file changes, appears or goes (NOTEBOOK_RULES_FROM, the file list they were written from).
# Without them (writing failed) every notebook depends on the whole library and data.
NOTEBOOK_RULES := book/notebooks/.inputs.mk
RULES_INPUTS := $(LIBRARY) $(DATA) $(NOTEBOOKS)
-include $(NOTEBOOK_RULES)
ifeq ($(NOTEBOOK_RULES_FROM),)
$(EXECUTED): $(LIBRARY) $(DATA)
endif

RULES_CHANGED := $(strip $(filter-out $(RULES_INPUTS),$(NOTEBOOK_RULES_FROM)) \
	$(filter-out $(NOTEBOOK_RULES_FROM),$(RULES_INPUTS)))

$(NOTEBOOK_RULES): $(RULES_INPUTS) $(if $(RULES_CHANGED),FORCE)
	@mkdir -p $(@D); rm -f $@; tmp=$@.tmp-$$$$; \
	if PYTHONPATH=src $(PYTHON) -m calstudy.io.dependencies $(@D) $(NOTEBOOKS) > $$tmp; \
	then echo 'NOTEBOOK_RULES_FROM := $(RULES_INPUTS)' >> $$tmp && mv $$tmp $@; \
	else rm -f $$tmp; echo "make: no $@: every notebook depends on all of src and data" >&2; \
		exit 1; fi

FORCE: ;

help: ## list the targets
	@echo "calstudy: make <target>"
	@grep -hE '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed -E 's/^([a-z-]+):.*## /  \1\t/' | expand -t 14

venv: $(STAMP) ## create .venv with the pinned dependencies and calstudy (editable)

# The pinned uv installs the pins in about a quarter of pip's time (parallel downloads, no
# byte-compiling: Python compiles a module on its first import). Where uv cannot be installed
# or cannot reach the package index, pip installs the same pins (--no-compile likewise).
$(STAMP): environment.txt pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	if $(BIN)/pip install --no-compile "$$(grep -E '^uv==' environment.txt)" \
		&& $(BIN)/uv pip install --python $(BIN)/python -r environment.txt; \
	then $(BIN)/uv pip install --python $(BIN)/python --no-deps -e .; \
	else echo "venv: uv failed; installing with pip" >&2; \
		$(BIN)/pip install --no-compile -r environment.txt \
		&& $(BIN)/pip install --no-compile --no-deps -e .; fi
	touch $@

# Notebooks run NOTEBOOK_JOBS at a time, longest first, so that the two at work end close
# together. While several run, each gets its share of the cores for its trials
# (LOKY_MAX_CPU_COUNT, which n_jobs=None reads as "all cores"): on 2 cores each runs its
# trials in its own process and no worker process has to start and import the library.
# With more than one at a time, each prints a line when it starts and ends instead of a bar.
NOTEBOOK_JOBS ?= 2
CORES := $(shell getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)
CORES_PER_NOTEBOOK := $(shell echo $$(( $(CORES) / $(NOTEBOOK_JOBS) > 0 ? $(CORES) / $(NOTEBOOK_JOBS) : 1 )))
# Seconds each took in a fresh `make reproduce` on 2 idle cores (one core each): 05 1,332,
# 04 1,249, 03 284, 02 187, 01 122, 06 9. A notebook not listed runs last.
LONGEST_FIRST := 05_dualarm_global_calibration 04_binocular_correction \
	03_selfcal_one_step_identification 02_hybrid_production_compensation \
	01_hybrid_global_calibration 06_handeye_your_cell
LISTED := $(foreach s,$(LONGEST_FIRST),$(filter book/notebooks/$(s).ipynb,$(EXECUTED)))
RUN_ORDER := $(LISTED) $(filter-out $(LISTED),$(EXECUTED))

reproduce: $(STAMP) ## run every notebook (two at a time), aggregate results/claims.csv, build the book
	@$(MAKE) --no-print-directory -j$(NOTEBOOK_JOBS) \
		NOTEBOOK_LINES=$(if $(filter 1,$(NOTEBOOK_JOBS)),,1) run-notebooks
	@$(MAKE) --no-print-directory $(BOOK_STAMP)
	@echo "reproduce: $(words $(EXECUTED)) notebook(s) up to date; book in book/_build/html"

notebooks: $(EXECUTED) ## run the notebooks whose inputs changed (writes results/<notebook>/)

# make starts the prerequisites of a goal in the order they are listed
run-notebooks: $(RUN_ORDER)
	@:

# An executed copy is the record that its notebook ran with default parameters; the notebook
# writes results/<stem>/ itself. Its inputs besides the notebook are in NOTEBOOK_RULES. Output goes to a temporary name first, so a failed run leaves
# no executed copy and is retried next time.
book/notebooks/%.ipynb: notebooks/%.ipynb $(STAMP)
	@mkdir -p $(@D)
ifeq ($(NOTEBOOK_LINES),)
	$(BIN)/papermill --cwd notebooks --progress-bar $< $(@D)/.tmp-$*.ipynb
else
	@echo "$*: running"; start=$$SECONDS; \
	LOKY_MAX_CPU_COUNT=$${LOKY_MAX_CPU_COUNT:-$(CORES_PER_NOTEBOOK)} $(BIN)/papermill --cwd notebooks --no-progress-bar $< $(@D)/.tmp-$*.ipynb 2>$(@D)/.tmp-$*.log \
		|| { cat $(@D)/.tmp-$*.log; exit 1; }; \
	echo "$*: done in $$((SECONDS - start)) s"; rm -f $(@D)/.tmp-$*.log
endif
	mv $(@D)/.tmp-$*.ipynb $@

results/claims.csv: $(EXECUTED) src/calstudy/io/results.py | $(STAMP)
	$(BIN)/python -c "from calstudy.io.results import aggregate_claims; aggregate_claims()"

book/claims.md: results/claims.csv data/claims.csv src/calstudy/io/book.py \
		src/calstudy/io/claims_cells.py src/calstudy/io/robustness_grid.py | $(STAMP)
	$(BIN)/python -m calstudy.io.book claims $@

book/ledger.md: $(DATA) src/calstudy/io/ledger.py src/calstudy/core/ledger.py | $(STAMP)
	$(BIN)/python -m calstudy.io.ledger $@

# Result files found at start-up; a notebook may stop writing one during this run.
$(RESULTS): ;

$(BOOK_STAMP): $(BOOK_SOURCES) $(EXECUTED) $(RESULTS) | $(STAMP)
	$(BIN)/jupyter-book build book/ --all --warningiserror --nitpick --keep-going
	touch $@

book: $(BOOK_STAMP) ## build the book (same as reproduce)

# The browser check opens the book in Debian's chromium ($$CHROMIUM names another binary). When
# it is missing, root installs it with apt-get (about a minute); anyone else is told the command.
CHROMIUM_INSTALL := apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium
browser: ## install Debian's chromium for the browser check when it is missing (as root)
	@if [ -n "$${CHROMIUM:-}" ] && command -v "$$CHROMIUM" >/dev/null 2>&1; then exit 0; fi; \
	if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "browser: installing Debian's chromium for the book check (apt-get)"; \
		$(CHROMIUM_INSTALL) >/dev/null || { echo "browser: apt-get could not install chromium" >&2; exit 1; }; \
	else \
		echo "browser: make test opens the book in Chromium and found none; run" >&2; \
		echo "    sudo $(CHROMIUM_INSTALL)" >&2; \
		echo "(or set CHROMIUM to a Chromium binary), then make test again" >&2; exit 1; \
	fi

test: $(STAMP) browser ## chromium if missing, ruff, the import layers, then pytest (unit tests, notebook runs, the book in Chromium)
	$(BIN)/ruff check src tests notebooks benchmarks
	$(BIN)/lint-imports
	$(BIN)/pytest

# pytest in `make test` runs tests/test_book.py too; this target runs only the browser check.
check-book: $(STAMP) browser ## build the book from CI-valued notebook runs in a temporary folder, open every page in headless Chromium
	$(BIN)/pytest -m book tests/test_book.py

verify: $(STAMP) ## rerun every notebook at its defaults and compare with the committed results/
	$(BIN)/pytest -m verify tests/test_notebooks.py

lint: $(STAMP) ## ruff check of src, tests, notebooks and benchmarks; the import layers
	$(BIN)/ruff check src tests notebooks benchmarks
	$(BIN)/lint-imports

bench: $(STAMP) ## time the speed budgets (prints; writes nothing)
	@for b in $(sort $(wildcard benchmarks/bench_*.py)); do echo "== $$b"; $(BIN)/python $$b; done

clean: ## remove the built book and executed notebooks (results/ and .venv stay)
	rm -rf book/_build book/notebooks book/claims.md book/claims-verdicts.png \
		book/claims-robustness.png book/claims-register.csv book/claims-results.csv book/claims-headline.md book/ledger.md \
		book/verdicts-*.md book/key-*.png
