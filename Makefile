# Two commands do everything: `make demo` (the showcase on simulators) and `make test` (the whole suite).
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed

.PHONY: demo test lint typecheck pytest bench soak bytecode clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[all,test]'
	$(MAKE) --no-print-directory bytecode
	touch $(STAMP)

# An editable install runs the sources in place: compile them as `pip install` compiles a wheel, so each command
# loads bytecode (also where PYTHONDONTWRITEBYTECODE keeps Python from writing it); only changed files recompile.
bytecode:
	$(BIN)/python -m compileall -q src

demo: $(STAMP) bytecode
	$(BIN)/fabwire demo

test: lint typecheck pytest

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

typecheck: $(STAMP)
	$(BIN)/mypy --strict src

# The suite runs on every CPU (pytest-xdist); tests that share something machine-wide (mDNS names) run in one group.
PYTEST_PARALLEL = -n auto --dist loadgroup

pytest: $(STAMP) bytecode
	scripts/ensure-system-packages
	$(BIN)/pytest -q $(PYTEST_PARALLEL)

# The whole suite and the long soak runs, with CPU burners beside them: what holds on a busy machine.
soak: $(STAMP) bytecode
	scripts/ensure-system-packages stress-ng
	scripts/under-load $(BIN)/pytest -q $(PYTEST_PARALLEL) --soak

bench: $(STAMP) bytecode
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
