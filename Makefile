# Both targets build .venv from nothing on a machine with only Python >= 3.11,
# and refresh it whenever pyproject.toml changes. The set-up ends by compiling every
# numba kernel once (`hydrojet-bench warmup`), so no later command, test worker or
# diagnosis worker process waits on a compile.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test perf clean

$(STAMP): pyproject.toml
	$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11) and "Python >= 3.11 is required" or 0)'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	$(BIN)/hydrojet-bench warmup
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/hydrojet-bench run --log sessions/demo.mcap --overwrite --report sessions/demo-report

# Many tests wait on emulated devices and subprocesses rather than compute, so the suite
# runs on one pytest worker per usable core (pytest-xdist); PYTEST_XDIST_AUTO_NUM_WORKERS
# overrides the count, and `pytest` alone runs serially.
test: $(STAMP)
	$(BIN)/python -m pytest -n auto

perf: $(STAMP)
	$(BIN)/hydrojet-bench perf

clean:
	rm -rf $(VENV) build *.egg-info
