# All set-up happens here: `make demo` and `make test` create .venv and install on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint bench clean

$(STAMP): pyproject.toml constraints.txt
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/adaptenv demo

test: $(STAMP)
	$(BIN)/ruff check src tests tools
	$(BIN)/pytest -n 2 -q
	$(BIN)/python tools/check_houses.py preset:tiny tests/data --episodes 10 --check

bench: $(STAMP)
	for b in sim expert houses render edits adapt train executor; do $(BIN)/adaptenv bench $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
