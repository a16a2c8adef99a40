# Two entry points: `make run` (the main job) and `make test` (the test suite).
# Each creates or refreshes .venv from pyproject.toml first.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test lint bench clean venv

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

run: $(STAMP)
	$(PY) -m cake_drake.run --mode torque

test: $(STAMP)
	$(PY) -m pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

bench: $(STAMP)
	$(PY) benchmarks/planning.py
	$(PY) benchmarks/ik.py
	$(PY) benchmarks/run.py
	$(PY) benchmarks/sweep.py models/sweeps/smoke.yaml models/sweeps/kd.yaml

clean:
	rm -rf $(VENV) outputs .pytest_cache
