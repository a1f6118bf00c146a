# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Both create the virtual environment when it is missing and install the pinned dependencies.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
export ANNY_CACHE_DIR ?= $(CURDIR)/.humancal/cache/anny

.PHONY: demo test test-all bench install clean-state

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch first: 2.13.0 resolves to the CPU build; anything unpinned would pull CUDA wheels.
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e '.[dev,cluster]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/humancal demo

# The tests run in parallel (one worker per file, TEST_WORKERS of them). The body model's cache is built first, once,
# so that the workers do not race to write it on a fresh machine.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(BIN)/python -c "from humancal.body import BodyModel; BodyModel()"
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

bench: $(STAMP)
	$(BIN)/python scripts/bench_body.py

clean-state:
	rm -rf .humancal/artifacts .humancal/dagster_home
