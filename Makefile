# nurbscnc — the two commands a newcomer needs are `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO   := programs/naca2415.nc
OUT    := out

.PHONY: install demo test lint unit bench reproduce clean goldens fuzz

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,plot]'
	touch $(STAMP)

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

unit: $(STAMP)
	$(BIN)/python -m pytest

test: lint unit

bench: $(STAMP)
	$(BIN)/python bench/run.py --out bench/results.json
	$(BIN)/python bench/interp_bench.py --out bench/interp_results.json
	$(BIN)/python bench/stream_bench.py --out bench/stream_results.json
	@if [ -f bench/plan_bench.py ]; then $(BIN)/python bench/plan_bench.py --out bench/plan_results.json; fi

# The fuzz tests with a large budget (make test runs them small): mutants of the corpus and
# hypothesis programs through check/plan; counts in out/fuzz-report.json.
FUZZ_EXAMPLES ?= 20000
FUZZ_SECONDS  ?= 240
fuzz: $(STAMP)
	@mkdir -p $(OUT)
	NURBSCNC_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) NURBSCNC_FUZZ_SECONDS=$(FUZZ_SECONDS) \
	NURBSCNC_FUZZ_REPORT=$(OUT)/fuzz-report.json \
	$(BIN)/python -m pytest tests/test_fuzz_cli.py -q -s

reproduce: $(STAMP)
	$(BIN)/python docs/make_reproduction.py --out docs/reproduction.md

# LinuxCNC's moves for tests/programs/real/ (needs LinuxCNC 2.9: /usr/bin/python3 with its
# `gcode` module, and rs274). The goldens are committed; CI does not need LinuxCNC.
goldens:
	/usr/bin/python3 tools/record_goldens.py
	/usr/bin/python3 tools/record_goldens.py --programs tests/programs/cycles --goldens tests/golden/linuxcnc_cycles
	/usr/bin/python3 tools/record_goldens.py --programs tests/programs/comp --goldens tests/golden/linuxcnc_comp

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
