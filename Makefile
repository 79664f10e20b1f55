# Two commands on a fresh clone (Python 3.11 and make):
#   make reproduce   set up .venv, reproduce the paper's scenarios into results/paper
#   make test        set up .venv (or reuse it), run the test suite
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
OUT ?= results/paper

.PHONY: setup reproduce test bench lint clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev,compare]"
	touch $(STAMP)

reproduce: $(STAMP)
	$(BIN)/auvmpc reproduce --out $(OUT) --overwrite

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/auvmpc bench

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

clean:
	rm -rf $(VENV) results runs
