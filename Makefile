# hexa — the two commands a user needs: `make demo` and `make test`. Both do all set-up (idempotent).
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
export MUJOCO_GL ?= egl
# Python keeps its bytecode caches (in .venv and in __pycache__/, git-ignored), also where the shell sets
# PYTHONDONTWRITEBYTECODE: the set-up installs the wheels without compiling them, and each of the hundreds of processes
# the tests start imports numpy, rclpy, mujoco & co.; without the caches every one compiled them again (1-2 s of CPU
# per process on a fresh clone).
unexport PYTHONDONTWRITEBYTECODE
PYTEST_ARGS ?=
# mypy's cache outside the checkout: a fresh clone re-checks only what changed (the stubs of numpy & co. stay cached)
MYPY := $(VENV)/bin/mypy --cache-dir $(HOME)/.cache/hexa-mypy

.PHONY: setup setup-robot test check lint demo bench firmware clean help

help:
	@echo "make demo   - set up, then run the main job on the simulated robot (hexa demo)"
	@echo "make test   - set up, build the firmware, run the whole test suite"
	@echo "make check  - set up, lint, run the fast tests (not marked slow: no ROS processes, simulator runs, simavr)"
	@echo "make bench  - set up, run the benchmarks (hexa bench)"
	@echo "make firmware - build the Arduino firmware (.hex) with Debian's AVR toolchain"
	@echo "make setup  - only the set-up (venv, ROS 2 Jazzy wheels, hexa_msgs, toolchains)"
	@echo "make setup-robot - the set-up plus the robot mode's optional packages (pyrealsense2)"

setup:
	@bash scripts/setup_env.sh

# Robot mode's optional packages (requirements/robot.txt: pyrealsense2), on top of the set-up.
setup-robot: setup
	@$(PY) -m pip install --disable-pip-version-check -q -r requirements/robot.txt

firmware: setup
	@if [ -f hexa_driver/firmware/Makefile ]; then $(MAKE) --no-print-directory -C hexa_driver/firmware; \
	else echo "firmware: hexa_driver/firmware/Makefile not present yet"; fi

# Lint first (ruff: pyflakes + pycodestyle; mypy on src/hexa; settings in pyproject.toml), then the tests: those that
# start no ROS processes on two workers, then the ROS ones one at a time, with the slowest listed at the end of each
# part (scripts/run_tests.sh; "no tests collected" is a failure there, not a pass).
test: setup-robot firmware
	@$(VENV)/bin/ruff check --quiet . || { echo "make test: ruff found problems (see above)" >&2; exit 1; }
	@$(MYPY) || { echo "make test: mypy found problems in src/hexa (see above)" >&2; exit 1; }
	@PY=$(PY) bash scripts/run_tests.sh $(PYTEST_ARGS)

# The fast part of the suite while you work (tests not marked `slow`, see test/conftest.py); CI runs everything.
check: setup
	@$(VENV)/bin/ruff check --quiet . || { echo "make check: ruff found problems (see above)" >&2; exit 1; }
	@$(MYPY) || { echo "make check: mypy found problems in src/hexa (see above)" >&2; exit 1; }
	@$(PY) -m pytest test/ -q -p no:cacheprovider -m "not slow" $(PYTEST_ARGS)

lint: setup
	@$(VENV)/bin/ruff check .

demo: setup firmware
	@$(VENV)/bin/hexa demo

bench: setup
	@$(VENV)/bin/hexa bench

clean:
	rm -rf build .pytest_cache
