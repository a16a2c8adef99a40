# Two entry points: `make run` (the main job) and `make test` (the test suite).
# Each first makes sure the Debian packages it needs (system-packages.txt) are installed,
# then creates or refreshes .venv from pyproject.toml: `make run` with the base
# dependencies only (what `python -m cake_drake.run` imports), `make test` with the
# `test` extra on top (the optional planners, OMPL, Ray, Gymnasium, LeRobot with torch).
# One .venv for both: `make test` after `make run` adds the extras, `make run` after
# `make test` installs nothing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
RUN_STAMP := $(VENV)/.installed-run
TEST_STAMP := $(VENV)/.installed-test
SYSTEM_PACKAGES := system-packages.txt

.PHONY: run test notebooks lint bench clean venv system-packages-run system-packages-test

# $(call ensure_packages,GOAL,GOALS): install the Debian packages system-packages.txt lists
# for any of GOALS that are missing: as root, or with password-less sudo; otherwise stop at
# once with the apt-get line to run. Without dpkg (not Debian) it only names them. Two makes
# at once (two checkouts) take turns at apt (a lock file, and apt's own lock waited for).
define ensure_packages
@want=$$(sed 's/#.*//' $(SYSTEM_PACKAGES) | awk -v goals=' $(2) ' \
	  'NF >= 2 && index(goals, " " $$2 " ") { print $$1 }'); \
if ! command -v dpkg-query >/dev/null 2>&1; then \
	echo "note: not a Debian system; make $(1) needs the equivalents of: $$want" >&2; \
	exit 0; \
fi; \
missing=""; \
for p in $$want; do \
	dpkg-query -W -f='$${Status}\n' "$$p" 2>/dev/null | grep -qx 'install ok installed' \
	  || missing="$$missing $$p"; \
done; \
missing=$${missing# }; \
[ -z "$$missing" ] && exit 0; \
if [ "$$(id -u)" = 0 ]; then sudo=""; \
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then sudo="sudo"; \
else \
	echo "error: make $(1) needs Debian packages that are not installed; run: sudo apt-get update && sudo apt-get install -y $$missing" >&2; \
	exit 1; \
fi; \
echo "make $(1): installing Debian packages: $$missing"; \
lock=""; command -v flock >/dev/null 2>&1 && lock="flock -w 900 /tmp/.cake_drake-apt.lock"; \
$$sudo $$lock apt-get -o DPkg::Lock::Timeout=900 update -qq && \
$$sudo $$lock env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=900 \
	install -y -qq --no-install-recommends $$missing >/dev/null
endef

system-packages-run:
	$(call ensure_packages,run,run)

system-packages-test:
	$(call ensure_packages,test,run test)

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# The base dependencies: refreshed when pyproject.toml changes. pip leaves installed
# extras alone (it removes nothing and upgrades only what a requirement asks for).
$(RUN_STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet -e .
	touch $(RUN_STAMP)

# The test extra on top: after the base install (so a changed pyproject.toml refreshes
# the base first, and both stamps are current afterwards).
$(TEST_STAMP): $(RUN_STAMP)
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(TEST_STAMP)

# The package's bytecode, compiled here rather than by each run: an editable install
# has none, and where PYTHONDONTWRITEBYTECODE is set Python would compile every module
# anew in every run (~0.1 s of each `python -m cake_drake.run`).
BYTECODE := $(VENV)/.bytecode
$(BYTECODE): $(RUN_STAMP) $(shell find cake_drake -name '*.py')
	$(PY) -m compileall -q cake_drake
	touch $(BYTECODE)

# The development environment: everything `make test` installs.
venv: $(TEST_STAMP) $(BYTECODE)

run: system-packages-run $(BYTECODE)
	$(PY) -m cake_drake.run --mode torque

test: system-packages-test $(TEST_STAMP) $(BYTECODE)
	$(PY) -m pytest

notebooks: system-packages-test $(TEST_STAMP) $(BYTECODE)
	$(PY) notebooks/refresh.py

lint: $(TEST_STAMP) $(BYTECODE)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

# The planning table compares Fast Downward too (the test extra has it).
bench: system-packages-run $(TEST_STAMP) $(BYTECODE)
	$(PY) benchmarks/planning.py
	$(PY) benchmarks/ik.py
	$(PY) benchmarks/run.py
	$(PY) benchmarks/sweep.py models/sweeps/smoke.yaml models/sweeps/kd.yaml

clean:
	rm -rf $(VENV) outputs .pytest_cache
