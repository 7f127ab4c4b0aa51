# groundfx: `make demo` sets up .venv and runs the main job; `make test` sets up and runs the tests.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: install demo test lint bench figures clean

# uv installs what pip resolves, the same versions, faster than pip. It reads no pip
# configuration: the local wheel cache that holds the CPU build of torch is passed on from
# pip's (PIP_FIND_LINKS, or pip.conf).
FIND_LINKS ?= $(or $(PIP_FIND_LINKS),$(shell $(PYTHON) -m pip config get global.find-links 2>/dev/null))
UV = $(BIN)/uv pip install --quiet --python $(BIN)/python $(foreach d,$(FIND_LINKS),--find-links $(d))

# Some machines set PYTHONDONTWRITEBYTECODE: every process (each flight's two) would then
# compile what it imports from source at every start. Here a module is compiled once, at its
# first import, and only what is imported (byte-compiling the whole environment at install
# took longer than the tests' own first imports).
unexport PYTHONDONTWRITEBYTECODE

$(BIN)/groundfx: pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet uv==0.13.9
	$(UV) -c constraints.txt -e '.[dev,ray,parquet]'
# MAVProxy for tests/test_mavproxy.py, without its GUI deps (wxPython, OpenCV, VTK)
	$(UV) --no-deps MAVProxy==1.8.75
	touch $@

install: $(BIN)/groundfx

demo: install
	$(BIN)/groundfx demo

test: install
	$(BIN)/ruff check .
# two workers (a flight's two processes take turns on one core), a test to whichever is free
	$(BIN)/pytest -q -n 2 --dist loadgroup

# every figure README.md and docs/ quote, from its seeded command (a few minutes; results in
# docs/results/, with the date, commit and load)
figures: install
	$(BIN)/groundfx figures

bench: install
	$(BIN)/groundfx bench sim --json

clean:
	rm -rf $(VENV) build *.egg-info
