# Two commands on a fresh clone (Python 3.11 and make):
#   make reproduce   set up .venv, reproduce the paper's scenarios into results/paper
#   make test        set up .venv (or reuse it), run the test suite
#   make docs        build the documentation site into site/ (strict)
#   make fuzz        the long fuzz profile: >= 10,000 hostile inputs (docs/safety.md)
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
OUT ?= results/paper

.PHONY: setup reproduce test fuzz bench lint docs clean blasfeo

setup: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev,compare,ros,ardupilot,video,docs]"
	touch $(STAMP)

reproduce: $(STAMP)
	$(BIN)/auvmpc reproduce --out $(OUT) --overwrite

# One pytest worker per core, at most four (each holds its own CasADi builds in memory).
TEST_WORKERS ?= $(shell $(PYTHON) -c "import os; print(min(4, os.cpu_count() or 1))")

test: $(STAMP)
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)

# The long fuzz profile (tests/fuzzing.py, docs/safety.md): >= 10,000 generated hostile
# inputs through the command line, each answered cleanly within 10 s; about 17 min on two
# cores. FUZZ_SEED=N draws another sequence; the short profile runs within `make test`.
FUZZ_SEED ?= 28
fuzz: $(STAMP)
	AUVMPC_FUZZ=long $(BIN)/python -m pytest -q -s -p no:cacheprovider \
		--hypothesis-seed=$(FUZZ_SEED) tests/test_fuzz_inputs.py tests/test_fuzz_run_folders.py

bench: $(STAMP)
	$(BIN)/auvmpc bench

# A BLASFEO built for x86-64 with AVX2 and FMA, for export-c --blasfeo and AUVMPC_BLASFEO_DIR
# (docs/onboard.md): fetched once from the package registry, never at run time.
BLASFEO_HASWELL := $(VENV)/blasfeo-x64-haswell
blasfeo: $(BLASFEO_HASWELL)/libblasfeo.so

$(BLASFEO_HASWELL)/libblasfeo.so: $(STAMP)
	$(BIN)/python benchmarks/blasfeo_haswell.py --out $(BLASFEO_HASWELL)

# The documentation site (mkdocs-material + mkdocstrings) into site/; strict: a broken
# link or reference fails the build.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples

clean:
	rm -rf $(VENV) results runs site
