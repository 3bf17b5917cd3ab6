# nurbscnc — the two commands a newcomer needs are `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO   := programs/naca2415.nc
OUT    := out

.PHONY: install demo test lint unit bench reproduce clean goldens fuzz

install: $(STAMP)

# Quiet: pip at -qq prints errors only; PYTHONWARNINGS silences setuptools' advice on
# editable installs (its BuildBackendWarning, a UserWarning) in the build's subprocess.
# setup.py builds the compiled kernels (nurbscnc/plan/_kernels.c, nurbscnc/geometry/_kernels.c;
# optional: without a C compiler the package installs and runs the same loops in Python).
$(STAMP): pyproject.toml setup.py nurbscnc/plan/_kernels.c nurbscnc/plan/_kernels_math.h nurbscnc/geometry/_kernels.c nurbscnc/geometry/_kernels_spiral.h
	@echo "installing nurbscnc and its dependencies into $(VENV) (1-2 minutes)"
	@$(PYTHON) -m venv $(VENV)
	@$(BIN)/python -m pip install --quiet --quiet --upgrade pip
	@PYTHONWARNINGS=ignore::UserWarning $(BIN)/python -m pip install --quiet --quiet -e '.[test,plot]'
	@touch $(STAMP)

demo: $(STAMP)
	@mkdir -p $(OUT)
	$(BIN)/nurbscnc check $(DEMO)
	$(BIN)/nurbscnc corners $(DEMO)
	$(BIN)/nurbscnc ph $(DEMO)
	$(BIN)/nurbscnc plan $(DEMO) --dump-profile $(OUT)/naca2415-profile.csv
	$(BIN)/nurbscnc run $(DEMO) -o $(OUT)/naca2415-points.csv
	@echo "reference points: $(OUT)/naca2415-points.csv"

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# Two workers (pytest-xdist; -n auto: one per core), each test file on one worker so its
# module fixtures (plans of whole programs) are made once. PYTEST_WORKERS=0: in-process.
PYTEST_WORKERS ?= auto
unit: $(STAMP)
	$(BIN)/python -m pytest -n $(PYTEST_WORKERS) --dist loadfile

test: lint unit

# `make bench` runs every benchmark and rewrites bench/*.json (docs/benchmarks.md explains
# each figure); `make bench BENCH_QUICK=1` runs the small subsets (a few minutes) and writes
# out/bench-quick/*.json instead, leaving the committed results alone.
BENCH_QUICK ?=
BENCH_OUT   := $(if $(BENCH_QUICK),$(OUT)/bench-quick,bench)
BENCH_FLAG  := $(if $(BENCH_QUICK),--quick,)
bench: $(STAMP)
	@mkdir -p $(BENCH_OUT)
	$(BIN)/python bench/run.py $(BENCH_FLAG) --out $(BENCH_OUT)/results.json
	$(BIN)/python bench/interp_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/interp_results.json
	$(BIN)/python bench/stream_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/stream_results.json
	$(BIN)/python bench/plan_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/plan_results.json
	$(BIN)/python bench/planner_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/planner_results.json
	$(BIN)/python bench/cam_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/cam_results.json
	$(BIN)/python bench/scale_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/scale_results.json
	$(BIN)/python bench/startup_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/startup_results.json
	$(BIN)/python bench/optimum.py $(BENCH_FLAG) --out $(BENCH_OUT)/optimum_results.json
	$(BIN)/python bench/table4.py $(BENCH_FLAG) --out $(BENCH_OUT)/table4_results.json
	$(BIN)/python bench/compile_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/compile_results.json
	$(BIN)/python bench/rotary_bench.py $(BENCH_FLAG) --out $(BENCH_OUT)/rotary_results.json

# The fuzz tests with a large budget (make test runs them small): mutants of the corpus and
# hypothesis programs through check/plan; counts in out/fuzz-report.json. Then the planner's
# honesty (bound below the plan, a higher F never slower) on FUZZ_EXAMPLES/200 random seeds;
# the grammar's properties on FUZZ_EXAMPLES/40 programs and lines.
FUZZ_EXAMPLES ?= 20000
FUZZ_SECONDS  ?= 240
fuzz: $(STAMP)
	@mkdir -p $(OUT)
	NURBSCNC_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) NURBSCNC_FUZZ_SECONDS=$(FUZZ_SECONDS) \
	NURBSCNC_FUZZ_REPORT=$(OUT)/fuzz-report.json \
	$(BIN)/python -m pytest tests/test_fuzz_cli.py -q -s
	NURBSCNC_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(BIN)/python -m pytest tests/test_plan_honesty.py -q
	NURBSCNC_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(BIN)/python -m pytest tests/test_grammar_properties.py -q

reproduce: $(STAMP)
	$(BIN)/python docs/make_reproduction.py --out docs/reproduction.md

# LinuxCNC's moves for tests/programs/real/ (needs LinuxCNC 2.9: /usr/bin/python3 with its
# `gcode` module, and rs274). The goldens are committed; CI does not need LinuxCNC.
goldens:
	/usr/bin/python3 tools/record_goldens.py
	/usr/bin/python3 tools/record_goldens.py --programs tests/programs/cycles --goldens tests/golden/linuxcnc_cycles
	/usr/bin/python3 tools/record_goldens.py --programs tests/programs/comp --goldens tests/golden/linuxcnc_comp
	/usr/bin/python3 tools/record_goldens.py --rotary --programs tests/programs/rotary --goldens tests/golden/linuxcnc_rotary
	/usr/bin/python3 tools/record_goldens.py --wrapped-ini tests/programs/rotary/wrapped/wrapped.ini --programs tests/programs/rotary/wrapped --goldens tests/golden/linuxcnc_rotary/wrapped

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
