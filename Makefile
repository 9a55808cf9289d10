# Two entry points for users: `make demo` and `make test`. Both set up a local
# virtual environment (.venv) on first use, install the project, build the FMU.
PY ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# test processes: one per core (the suite is CPU-bound; CI has 2 cores); worksteal: the long
# close-loop tests otherwise queue on one worker at the end while the other idles
JOBS ?= $(shell nproc 2>/dev/null || echo 2)

.PHONY: all fmu demo test test-slow venv clean

all: fmu

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

fmu: $(STAMP)
	$(VPY) -m lss_fmu.build

demo: fmu
	$(VENV)/bin/lss demo --out demo_out

# make test leaves out the long cases marked slow (each repeats what a faster case checks on
# another record, seed, optimisation level or code path); make test-slow runs them (about an hour of CPU)
test: fmu
	$(VPY) -m pytest -q -p no:cacheprovider --durations=25 -n $(JOBS) --dist worksteal -m "not slow" tests

test-slow: fmu
	$(VPY) -m pytest -q -p no:cacheprovider --durations=25 -n $(JOBS) --dist worksteal -m slow tests

clean:
	rm -rf build demo_out
