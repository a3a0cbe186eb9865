# shapebag: `make help` lists the commands.
PY      ?= python3
VENV    ?= .venv
BIN     := $(VENV)/bin
DATA    ?= var/data
DEMO    ?= var/demo
PORT    ?= 8000
DATASET ?= ../shared/datasets/shrec11-simplified
DOCKER_UP ?= ../shared/containers/docker-up.sh
SHIPPED_VOCAB   := app/data/vocabulary/default
VOCAB_CLASSES   ?= 8
VOCAB_PER_CLASS ?= 12

.DEFAULT_GOAL := help
.PHONY: help install run serve test test-fast test-scale postgres chromium lint format evaluate vocabulary bench docker-lint docker-test mutate clean clean-demo clean-data

help:  ## list the commands
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) \
	  | sed 's|\$$(PORT)|$(PORT)|g; s|\$$(DATA)|$(DATA)|g; s|\$$(DEMO)|$(DEMO)|g' \
	  | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

$(BIN)/shapebag: pyproject.toml
	@echo "installing shapebag and its dependencies into $(VENV) (the first time: a minute or two) ..."
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[dev]'
	@touch $@

install: $(BIN)/shapebag  ## create .venv and install shapebag with its dev tools

run: install  ## quick start: the synthetic demo corpus in $(DEMO), served on 127.0.0.1:$(PORT) (dev mode)
	$(BIN)/shapebag demo --data-dir $(DEMO) --port $(PORT)

serve: install  ## serve your own data directory $(DATA) (empty at first; dev mode unless SHAPEBAG_ADMIN_TOKEN is set)
	$(BIN)/shapebag serve --data-dir $(DATA) --port $(PORT) $$([ -z "$$SHAPEBAG_ADMIN_TOKEN" ] && echo --dev)

test: install chromium  ## the whole suite, ~15 min on 2 cores; starts (then stops) a Docker engine
	$(BIN)/pytest -q

chromium:  ## Debian's chromium for the browser tests (installed as root; otherwise says they will skip)
	@bash .ci/chromium.sh

test-scale: install postgres  ## PostgreSQL suites (claim race, killed worker, 2 API processes) + the scaled compose kill test
	SHAPEBAG_TEST_POSTGRES=1 $(BIN)/pytest -q -ra -m "postgres or docker" tests/storage \
	  tests/services/test_both_engines.py tests/deploy/test_api_processes.py tests/deploy/test_scale_compose.py

postgres:  ## Debian's postgresql for test-scale (installed as root; otherwise says its cases will skip)
	@bash .ci/postgres.sh

test-fast: install  ## the suite without slow (dataset-wide, multi-process) tests
	$(BIN)/pytest -q -m "not slow and not docker"

lint: install  ## ruff + mypy
	$(BIN)/ruff check app tests benchmarks
	$(BIN)/mypy app

format: install  ## ruff format + autofix
	$(BIN)/ruff check --fix app tests benchmarks
	$(BIN)/ruff format app tests benchmarks

evaluate: install  ## Table 2 on SHREC'11 (DATASET=...)
	$(BIN)/shapebag evaluate $(DATASET)

vocabulary: install  ## refit the shipped app/data/vocabulary/default (synthetic corpus VOCAB_CLASSES x VOCAB_PER_CLASS, seed 0)
	rm -rf var/corpus-vocab var/vocabulary-default
	$(BIN)/python -c "from app.datasets.synthetic import generate; generate('var/corpus-vocab', classes=$(VOCAB_CLASSES), per_class=$(VOCAB_PER_CLASS), seed=0)"
	$(BIN)/shapebag vocabulary fit var/corpus-vocab --out var/vocabulary-default --size 64 --run run5 --seed 0
	@echo "compare with $(SHIPPED_VOCAB), then: rm -rf $(SHIPPED_VOCAB) && mv var/vocabulary-default $(SHIPPED_VOCAB)"

bench: install  ## short benchmark suite (prints tables, writes results/*.json)
	$(BIN)/python -m benchmarks.run --short

MUTATE          ?=
MUTATE_CHILDREN ?= 1

mutate: install  ## mutation testing (mutmut) of app/core + listed api/services/storage modules; score per module
	@# MUTATE='app.storage.jobs* app.core.hks*' limits the run to those mutant names (default: all).
	@# The tests find ../shared/datasets relative to their own path, one level deeper under mutants/:
	@# a link shared -> ../shared lives only while mutmut runs.
	@created=; if [ ! -e shared ]; then ln -s ../shared shared; created=1; fi; \
	$(BIN)/mutmut run --max-children $(MUTATE_CHILDREN) $(MUTATE); rc=$$?; \
	if [ -n "$$created" ]; then rm -f shared; fi; \
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
