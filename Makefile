# shapebag: `make help` lists the commands.
PY      ?= python3
VENV    ?= .venv
BIN     := $(VENV)/bin
# your data directory and port: SHAPEBAG_DATA_DIR / SHAPEBAG_PORT as the service reads them, else data/ (data/README.md)
DATA    ?= $(or $(SHAPEBAG_DATA_DIR),data)
DEMO    ?= var/demo
PORT    ?= $(or $(SHAPEBAG_PORT),8000)
# the evaluation datasets, never in the repository: SHAPEBAG_DATASETS, else ../shared/datasets beside it
DATASETS ?= $(or $(SHAPEBAG_DATASETS),../shared/datasets)
export SHAPEBAG_DATASETS := $(abspath $(DATASETS))
DATASET ?= $(SHAPEBAG_DATASETS)/shrec11-simplified
# the exact versions installed (pyproject.toml keeps the ranges; `make lock` rewrites these)
LOCK    := requirements/dev.lock
LOCKS   := requirements/base.lock requirements/postgres.lock $(LOCK)
# make test's parallel pytest processes (pytest-xdist): auto = one per core; a module's tests stay on one
# process, so its module-scoped servers and data dirs are built once
TEST_WORKERS ?= auto
XDIST   := -n $(TEST_WORKERS) --dist loadscope
DOCKER_UP ?= ../shared/containers/docker-up.sh
SHIPPED_VOCAB   := app/data/vocabulary/default
VOCAB_CLASSES   ?= 8
VOCAB_PER_CLASS ?= 12

.DEFAULT_GOAL := help
.PHONY: help docs install lock run serve test test-all test-fast test-scale postgres chromium lint format evaluate vocabulary bench docker-lint docker-test mutate clean clean-demo clean-data

help:  ## list the commands
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) \
	  | sed 's|\$$(PORT)|$(PORT)|g; s|\$$(DATA)|$(DATA)|g; s|\$$(DEMO)|$(DEMO)|g; s|\$$(LOCK)|$(LOCK)|g' \
	  | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

# stops a target that needs a dataset, naming it and how to get it: $(call need_dataset,FOLDER,NAME,MARKER)
need_dataset = @test -f "$(1)/$(3)" || { echo "make: dataset $(2) not found at $(1): set SHAPEBAG_DATASETS \
to the folder holding $(2)/ (data/README.md says how to get it)" >&2; exit 2; }

$(BIN)/shapebag: pyproject.toml $(LOCK)
	@echo "installing shapebag and the locked versions of its dependencies into $(VENV) (the first time: a minute or two) ..."
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q --require-hashes -r $(LOCK)
	$(BIN)/pip install -q --no-deps -e .
	@touch $@

install: $(BIN)/shapebag  ## create .venv: the locked dependencies ($(LOCK)) and shapebag, editable

lock: install  ## rewrite requirements/*.lock (hashes) from pyproject.toml's ranges: UPGRADE=1 takes the newest
	@for extras in base postgres dev; do \
	  flags=$$([ $$extras = base ] || echo "--extra $$extras"); \
	  $(BIN)/uv pip compile pyproject.toml $$flags --universal --python-version 3.11 --generate-hashes \
	    $$([ "$(UPGRADE)" = 1 ] && echo --upgrade) --quiet --no-header -o requirements/$$extras.lock || exit 1; \
	done; echo "wrote $(LOCKS): review, then make install"

run: install  ## quick start: the synthetic demo corpus in $(DEMO), served on 127.0.0.1:$(PORT) (dev mode)
	$(BIN)/shapebag demo --data-dir $(DEMO) --port $(PORT)

serve: install  ## serve your data directory $(DATA)/ (SHAPEBAG_DATA_DIR; empty at first; dev mode unless SHAPEBAG_ADMIN_TOKEN is set)
	$(BIN)/shapebag serve --data-dir $(DATA) --port $(PORT) $$([ -z "$$SHAPEBAG_ADMIN_TOKEN" ] && echo --dev)

test: install  ## the quick suite, in parallel (a few minutes on 2 cores); tests needing a dataset skip, saying which
	$(BIN)/pytest -q $(XDIST) -m "not slow and not docker"

test-all: install chromium  ## everything, what CI runs: + dataset-wide, live servers, browsers, Docker (~15 min on 2 cores)
	$(BIN)/pytest -q $(XDIST) -m "not slow and not docker"
	$(BIN)/pytest -q -m "slow or docker"

chromium:  ## Debian's chromium for the browser tests (installed as root; otherwise says they will skip)
	@bash .ci/chromium.sh

test-scale: install postgres  ## PostgreSQL suites (claim race, killed worker, 2 API processes) + the scaled compose kill test
	SHAPEBAG_TEST_POSTGRES=1 $(BIN)/pytest -q -ra -m "postgres or docker" tests/storage \
	  tests/services/test_both_engines.py tests/deploy/test_api_processes.py tests/deploy/test_scale_compose.py

postgres:  ## Debian's postgresql for test-scale (installed as root; otherwise says its cases will skip)
	@bash .ci/postgres.sh

test-fast: test  # the former name of `make test`

docs: install  ## the documentation site (MkDocs Material) built strictly into site/: a broken link or a page outside the nav fails
	$(BIN)/mkdocs build --strict --site-dir site

lint: install  ## ruff + mypy
	$(BIN)/ruff check app tests benchmarks
	$(BIN)/mypy app

format: install  ## ruff format + autofix
	$(BIN)/ruff check --fix app tests benchmarks
	$(BIN)/ruff format app tests benchmarks

evaluate: install  ## Table 2 on SHREC'11 (SHAPEBAG_DATASETS or DATASET=folder-with-labels.csv)
	$(call need_dataset,$(DATASET),shrec11-simplified,labels.csv)
	$(BIN)/shapebag evaluate $(DATASET)

# one BLAS/OpenMP thread throughout: the same files from the same code on one machine (pool processes pin
# themselves; the variables also cover the corpus generation and the command's own process)
PINNED := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONHASHSEED=0

vocabulary: install  ## refit the shipped app/data/vocabulary/default (synthetic corpus VOCAB_CLASSES x VOCAB_PER_CLASS, seed 0)
	rm -rf var/corpus-vocab var/corpus-vocab-fine var/vocabulary-default
	$(PINNED) $(BIN)/python -c "from app.datasets.synthetic import generate; generate('var/corpus-vocab', classes=$(VOCAB_CLASSES), per_class=$(VOCAB_PER_CLASS), seed=0)"
	$(PINNED) $(BIN)/python -c "from app.datasets.synthetic import refine; refine('var/corpus-vocab', 'var/corpus-vocab-fine', min_vertices=12000)"
	$(PINNED) $(BIN)/shapebag vocabulary fit var/corpus-vocab var/corpus-vocab-fine --out var/vocabulary-default --size 64 --run run5 --seed 0
	@echo "compare with $(SHIPPED_VOCAB), then: rm -rf $(SHIPPED_VOCAB) && mv var/vocabulary-default $(SHIPPED_VOCAB)"

bench: install  ## short benchmark suite on SHREC'11 (prints tables, writes results/*.json)
	$(call need_dataset,$(DATASET),shrec11-simplified,labels.csv)
	$(BIN)/python -m benchmarks.run --short

MUTATE          ?=
MUTATE_CHILDREN ?= 1

mutate: install  ## mutation testing (mutmut) of app/core + listed api/services/storage modules; score per module
	@# MUTATE='app.storage.jobs* app.core.hks*' limits the run to those mutant names (default: all).
	@# The tests under mutants/ find the datasets through SHAPEBAG_DATASETS, exported above as an absolute path.
	$(BIN)/mutmut run --max-children $(MUTATE_CHILDREN) $(MUTATE); rc=$$?; \
	$(BIN)/python tools/mutation_report.py; exit $$rc

docker-lint: install  ## hadolint the Dockerfile; `docker compose config -q` where compose v2 is installed
	$(BIN)/hadolint Dockerfile && echo "Dockerfile: hadolint clean"
	@plugin=$$(bash $(DOCKER_UP) --env 2>/dev/null | sed -n 's/^export DOCKER_CONFIG=//p'); \
	if [ -n "$$plugin" ] && [ -x "$$plugin/cli-plugins/docker-compose" ]; then export DOCKER_CONFIG=$$plugin; fi; \
	if docker compose version >/dev/null 2>&1; then \
	  SHAPEBAG_ADMIN_TOKEN=$${SHAPEBAG_ADMIN_TOKEN:-lint} docker compose config -q && echo "docker-compose.yml: valid"; \
	else echo "docker-compose.yml: NOT validated (no docker compose v2 here; $(DOCKER_UP) installs it)"; fi

docker-test: install  ## the compose stack on a real engine: build, ingest, search, restart, scale
	$(BIN)/pytest -q -m docker tests/deploy

clean:  ## remove caches (keeps .venv, $(DEMO) and $(DATA))
	rm -rf .pytest_cache .ruff_cache .mypy_cache results .cache

clean-demo:  ## delete the demo data dir $(DEMO) (`make run` regenerates it)
	rm -rf $(DEMO)

clean-data:  ## delete YOUR data dir $(DATA): models, index, vocabularies (asks first; CONFIRM=1 skips)
	@if [ -d $(DATA) ] && [ "$(CONFIRM)" != 1 ]; then \
	  printf "delete %s and everything in it? [y/N] " "$(DATA)"; read answer; [ "$$answer" = y ] || exit 1; fi
	rm -rf $(DATA)
