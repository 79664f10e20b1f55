# Two commands on a fresh clone (Python 3.11 and make):
#   make reproduce   set up .venv, reproduce the paper's scenarios into results/paper
#   make test        set up .venv (or reuse it), run the test suite
#   make docs        build the documentation site into site/ (strict)
#   make fuzz        the long fuzz profile: >= 10,000 hostile inputs (docs/safety.md)
#   make verify-arm  the exported C controller cross-built for aarch64 and checked under qemu
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
OUT ?= results/paper

.PHONY: setup reproduce test fuzz bench lint docs clean blasfeo blasfeo-avx blasfeo-aarch64 \
	hpipm-aarch64 verify-arm

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

# A BLASFEO built for x86-64 with AVX2 and FMA, for export-c --blasfeo and AUVMPC_BLASFEO_DIR,
# and one for 64-bit Arm with NEON (docs/onboard.md): fetched once from the package registry,
# never at run time; as are the aarch64 HPIPM and BLASFEO an export carries for TARGET=aarch64.
# Once fetched they stay (order-only on the setup: a reinstall does not fetch them again).
BLASFEO_HASWELL := $(VENV)/blasfeo-x64-haswell
BLASFEO_SANDY_BRIDGE := $(VENV)/blasfeo-x64-sandy-bridge
BLASFEO_A57 := $(VENV)/blasfeo-armv8a-a57
HPIPM_AARCH64 := $(VENV)/hpipm-aarch64
blasfeo: $(BLASFEO_HASWELL)/libblasfeo.so
blasfeo-avx: $(BLASFEO_SANDY_BRIDGE)/libblasfeo.so
blasfeo-aarch64: $(BLASFEO_A57)/libblasfeo.so
hpipm-aarch64: $(HPIPM_AARCH64)/libdaqp.so

$(BLASFEO_HASWELL)/libblasfeo.so: | $(STAMP)
	$(BIN)/python benchmarks/blasfeo_tuned.py --out $(BLASFEO_HASWELL)

# The generic x86-64 build's BLASFEO for AVX (export-c --generic-blasfeo): no package ships
# it, so it is built here from the BLASFEO sources a pinned wheel carries (gcc, cmake).
$(BLASFEO_SANDY_BRIDGE)/libblasfeo.so: | $(STAMP)
	$(BIN)/python benchmarks/blasfeo_avx.py --out $(BLASFEO_SANDY_BRIDGE)

$(BLASFEO_A57)/libblasfeo.so: | $(STAMP)
	$(BIN)/python benchmarks/blasfeo_tuned.py --machine aarch64 --out $(BLASFEO_A57)

# With DAQP (a six-dof export's depth MPC): a folder fetched before it held DAQP is fetched
# again whole (it holds nothing but what this rule fetched).
$(HPIPM_AARCH64)/libdaqp.so: | $(STAMP)
	rm -rf $(HPIPM_AARCH64)
	$(BIN)/python benchmarks/hpipm_aarch64.py --out $(HPIPM_AARCH64)

# The exported controller on the vehicle's ARM computer, checked here (docs/onboard.md): a
# closed loop of paper-obstacles with the exported controller, its export with the aarch64
# HPIPM and the NEON BLASFEO, cross-built (gcc-aarch64-linux-gnu) and replayed under
# qemu-aarch64 for both aarch64 targets: within 1e-6 N, the same statuses, no heap call in a
# step; then the same for 60 s of the 6-DOF helix (the horizontal nmpc and the depth MPC, no
# sensor noise: the replay reads the true states). About 3 minutes.
ARM_OUT ?= results/verify-arm
HELIX := bluerov2-helix --set duration=60
QUIET := --set 'sensing.std=[0,0,0,0,0,0]' --set sensing.depth_std_m=0 \
	--set sensing.depth_rate_std_m_per_s=0
verify-arm: $(HPIPM_AARCH64)/libdaqp.so $(BLASFEO_A57)/libblasfeo.so
	$(BIN)/auvmpc run paper-obstacles --set controller.type=nmpc \
		--set controller.control_horizon=null --no-figures --overwrite --out $(ARM_OUT)/run
	$(BIN)/auvmpc export-c paper-obstacles --aarch64 $(HPIPM_AARCH64) --blasfeo $(BLASFEO_A57) \
		--overwrite --out $(ARM_OUT)/export
	$(BIN)/auvmpc verify-c $(ARM_OUT)/export $(ARM_OUT)/run --target aarch64 --instructions
	$(BIN)/auvmpc verify-c $(ARM_OUT)/export $(ARM_OUT)/run --target aarch64-tuned
	$(BIN)/auvmpc run $(HELIX) --set controller.type=nmpc --set controller.control_horizon=null \
		$(QUIET) --no-figures --overwrite --out $(ARM_OUT)/helix-run
	$(BIN)/auvmpc export-c $(HELIX) --aarch64 $(HPIPM_AARCH64) --blasfeo $(BLASFEO_A57) \
		--overwrite --out $(ARM_OUT)/helix-export
	$(BIN)/auvmpc verify-c $(ARM_OUT)/helix-export $(ARM_OUT)/helix-run --target aarch64 \
		--instructions
	$(BIN)/auvmpc verify-c $(ARM_OUT)/helix-export $(ARM_OUT)/helix-run --target aarch64-tuned

# The documentation site (mkdocs-material + mkdocstrings) into site/; strict: a broken
# link or reference fails the build.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples

clean:
	rm -rf $(VENV) results runs site
