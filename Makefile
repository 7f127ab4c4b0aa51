# groundfx: `make demo` sets up .venv and runs the main job; `make test` sets up and runs the tests.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: install compile demo test lint bench clean

$(BIN)/groundfx: pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[dev,ray,parquet]'
# MAVProxy for tests/test_mavproxy.py, without its GUI deps (wxPython, OpenCV, VTK)
	$(BIN)/pip install --quiet --no-deps MAVProxy==1.8.75
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
# two workers, a test file each: a flight's two processes take turns on one core
	$(BIN)/pytest -q -n 2 --dist loadfile

bench: compile
	$(BIN)/groundfx bench sim --json

clean:
	rm -rf $(VENV) build *.egg-info
