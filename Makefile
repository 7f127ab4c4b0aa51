# groundfx: `make demo` sets up .venv and runs the main job; `make test` sets up and runs the tests.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: install compile demo test lint bench figures clean

# uv installs what pip resolves, the same versions, faster than pip. It reads no pip
# configuration: the local wheel cache that holds the CPU build of torch is passed on from
# pip's (PIP_FIND_LINKS, or pip.conf). Byte-compiled as pip does: these machines set
# PYTHONDONTWRITEBYTECODE, so an uncompiled package is compiled at every import.
FIND_LINKS ?= $(or $(PIP_FIND_LINKS),$(shell $(PYTHON) -m pip config get global.find-links 2>/dev/null))
UV = $(BIN)/uv pip install --quiet --compile-bytecode --python $(BIN)/python $(foreach d,$(FIND_LINKS),--find-links $(d))

$(BIN)/groundfx: pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet uv==0.13.9
	$(UV) -c constraints.txt -e '.[dev,ray,parquet]'
# MAVProxy for tests/test_mavproxy.py, without its GUI deps (wxPython, OpenCV, VTK)
	$(UV) --no-deps MAVProxy==1.8.75
	touch $@

install: $(BIN)/groundfx

# These machines set PYTHONDONTWRITEBYTECODE: without this every process (each flight's two)
# compiled our modules from source at every start (0.4 s of a flight's start-up). Only what
# changed is compiled again.
compile: install
	$(BIN)/python -m compileall -q autopilot simbridge learner mission > /dev/null

demo: compile
	$(BIN)/groundfx demo

test: compile
	$(BIN)/ruff check .
# two workers (a flight's two processes take turns on one core), a test to whichever is free
	$(BIN)/pytest -q -n 2 --dist loadgroup

# every figure README.md and docs/ quote, from its seeded command (a few minutes; results in
# docs/results/, with the date, commit and load)
figures: compile
	$(BIN)/groundfx figures

bench: compile
	$(BIN)/groundfx bench sim --json

clean:
	rm -rf $(VENV) build *.egg-info
