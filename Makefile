# astrodyn: set-up, tests, demo.  Everything runs inside .venv at the repo root.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp

.PHONY: install test test-all demo bench clean

$(STAMP): pyproject.toml setup.py src/astrodyn/messages/floatlayout.c
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test,plot]'
	@touch $(STAMP)

install: $(STAMP)

# The one CI command: the layer contract (import-linter, [tool.importlinter] in
# pyproject.toml), ruff, then the representative suite (slow exhaustive sweeps excluded),
# on two pytest-xdist workers, each test file on one worker (--dist loadfile): most of the
# suite's time is processes starting (imports, numba's target, kernels from the cache), which
# one pytest process left at about one busy core of two (fresh clone: 1020 s serial, 621 s
# on two workers).  TEST_WORKERS=0 runs it in one process.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(VENV)/bin/lint-imports && $(VENV)/bin/ruff check src tests && \
	$(PY) -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadfile)

# Everything, slow sweeps included.
test-all: $(STAMP)
	$(PY) -m pytest -q -m ''

# The main job: the demo scenario.
demo: $(STAMP)
	$(VENV)/bin/astrodyn demo

bench: $(STAMP)
	$(PY) -m pip install -q -e '.[test,plot,bench]'
	$(VENV)/bin/astrodyn bench all

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache
