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
	$(filter-out book/claims.md,$(wildcard book/*.md)) book/claims.md \
	$(wildcard book/_ext/*.py) $(wildcard book/_static/*)
BOOK_STAMP := book/_build/html/.built

.PHONY: help venv reproduce notebooks test check-book verify lint book bench clean

help: ## list the targets
	@echo "calstudy: make <target>"
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | sed -E 's/^([a-z-]+):.*## /  \1\t/' | expand -t 14

venv: $(STAMP) ## create .venv with the pinned dependencies and calstudy (editable)

# --no-compile: Python compiles a module on its first import instead; byte-compiling every file
# of every package at install time costs about 30 s of the 105 s the environment takes on 2 cores.
$(STAMP): environment.txt pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --no-compile -r environment.txt
	$(BIN)/pip install --no-compile --no-deps -e .
	touch $@

# Notebooks run NOTEBOOK_JOBS at a time (each spreads its trials over all cores; a second one
# fills the cores while the first starts its kernel, writes its tables and draws its figures).
# With more than one at a time, each prints a line when it starts and ends instead of a bar.
NOTEBOOK_JOBS ?= 2

reproduce: $(STAMP) ## run every notebook (two at a time), aggregate results/claims.csv, build the book
	@$(MAKE) --no-print-directory -j$(NOTEBOOK_JOBS) \
		NOTEBOOK_LINES=$(if $(filter 1,$(NOTEBOOK_JOBS)),,1) $(BOOK_STAMP)
	@echo "reproduce: $(words $(EXECUTED)) notebook(s) up to date; book in book/_build/html"

notebooks: $(EXECUTED) ## run the notebooks whose inputs changed (writes results/<notebook>/)

# An executed copy is the record that its notebook ran with default parameters; the notebook
# writes results/<stem>/ itself. Output goes to a temporary name first, so a failed run leaves
# no executed copy and is retried next time.
book/notebooks/%.ipynb: notebooks/%.ipynb $(LIBRARY) $(DATA) $(STAMP)
	@mkdir -p $(@D)
ifeq ($(NOTEBOOK_LINES),)
	$(BIN)/papermill --cwd notebooks --progress-bar $< $(@D)/.tmp-$*.ipynb
else
	@echo "$*: running"; start=$$SECONDS; \
	$(BIN)/papermill --cwd notebooks --no-progress-bar $< $(@D)/.tmp-$*.ipynb 2>$(@D)/.tmp-$*.log \
		|| { cat $(@D)/.tmp-$*.log; exit 1; }; \
	echo "$*: done in $$((SECONDS - start)) s"; rm -f $(@D)/.tmp-$*.log
endif
	mv $(@D)/.tmp-$*.ipynb $@

results/claims.csv: $(EXECUTED) src/calstudy/io/results.py | $(STAMP)
	$(BIN)/python -c "from calstudy.io.results import aggregate_claims; aggregate_claims()"

book/claims.md: results/claims.csv data/claims.csv src/calstudy/io/book.py \
		src/calstudy/io/claims_cells.py | $(STAMP)
	$(BIN)/python -m calstudy.io.book claims $@

# Result files found at start-up; a notebook may stop writing one during this run.
$(RESULTS): ;

$(BOOK_STAMP): $(BOOK_SOURCES) $(EXECUTED) $(RESULTS) | $(STAMP)
	$(BIN)/jupyter-book build book/ --all --warningiserror --nitpick --keep-going
	touch $@

book: $(BOOK_STAMP) ## build the book (same as reproduce)

test: $(STAMP) ## ruff, the import layers, then pytest (unit tests, notebook runs, the book in Chromium)
	$(BIN)/ruff check src tests notebooks benchmarks
	$(BIN)/lint-imports
	$(BIN)/pytest

# pytest in `make test` runs tests/test_book.py too; this target runs only the browser check.
check-book: $(STAMP) ## build the book from CI-valued notebook runs in a temporary folder, open every page in headless Chromium
	$(BIN)/pytest -m book tests/test_book.py

verify: $(STAMP) ## rerun every notebook at its defaults and compare with the committed results/
	$(BIN)/pytest -m verify tests/test_notebooks.py

lint: $(STAMP) ## ruff check of src, tests, notebooks and benchmarks; the import layers
	$(BIN)/ruff check src tests notebooks benchmarks
	$(BIN)/lint-imports

bench: $(STAMP) ## time the speed budgets of the issues (prints; writes nothing)
	@for b in $(sort $(wildcard benchmarks/bench_*.py)); do echo "== $$b"; $(BIN)/python $$b; done

clean: ## remove the built book and executed notebooks (results/ and .venv stay)
	rm -rf book/_build book/notebooks book/claims.md book/claims-verdicts.png \
		book/claims-register.csv book/claims-results.csv
