# All set-up happens here: `make demo` and `make test` create .venv and install on first use.
# `make demo` installs adaptenv with only its runtime dependencies; `make test` adds the dev extras
# (pytest, ruff, Ray, TensorBoard, MiniGrid), which the demo does not need.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev

.PHONY: install install-dev demo test lint bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(STAMP): pyproject.toml constraints.txt | $(BIN)/python
	$(BIN)/pip install --quiet -c constraints.txt -e .
	touch $(STAMP)

$(DEV_STAMP): $(STAMP)
	$(BIN)/pip install --quiet -c constraints.txt -e ".[dev]"
	touch $(DEV_STAMP)

install: $(STAMP)

install-dev: $(DEV_STAMP)

demo: $(STAMP)
	$(BIN)/adaptenv demo

test: $(DEV_STAMP)
	$(BIN)/ruff check src tests tools
	$(BIN)/pytest -n 2 --dist loadgroup -q --durations=30
	$(BIN)/python tools/check_houses.py preset:tiny tests/data --episodes 10 --check

bench: $(STAMP)
	for b in sim expert houses render edits adapt train executor; do $(BIN)/adaptenv bench $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
