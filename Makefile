# Two entry points for a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test lint bench reproduce-tests clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q -e '.[test]'
	$(BIN)/navreplay warm-up
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/navreplay demo

lint: $(STAMP)
	$(BIN)/ruff check navreplay tests benchmarks docs
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -q

reproduce-tests: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

bench: $(STAMP)
	$(BIN)/python -m benchmarks

clean:
	rm -rf $(VENV) build *.egg-info
