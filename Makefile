# Two entry points, each bootstraps .venv from scratch on a fresh machine:
#   make demo   render -> calibrate -> segment -> track, report and pictures in results/demo
#   make test   lint, format check, unit tests and notebooks
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
# Single-threaded OpenBLAS (cslx.environment): its threaded Cholesky stalls MED on 2 cores.
export OPENBLAS_NUM_THREADS := 1
# The notebooks' kernels compile like the tests (tests/conftest.py, TEST_XLA_FLAGS): LLVM -O0.
TEST_XLA_FLAGS := $(strip $(XLA_FLAGS) --xla_backend_optimization_level=0)

.PHONY: demo test clean

$(BIN)/cslx: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(BIN)/cslx

demo: $(BIN)/cslx
	$(BIN)/cslx demo --out results/demo

test: $(BIN)/cslx
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python -m pytest -n auto -q --durations=15 tests
	if ls notebooks/*.ipynb >/dev/null 2>&1; then XLA_FLAGS="$(TEST_XLA_FLAGS)" $(BIN)/python -m pytest -n auto -q --nbmake notebooks; fi

clean:
	rm -rf $(VENV) .pytest_cache
