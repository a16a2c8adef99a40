# Two entry points: `make run` (the main job) and `make test` (the test suite).
# Each first makes sure the Debian packages it needs (system-packages.txt) are installed,
# then creates or refreshes .venv from pyproject.toml: `make run` with the base
# dependencies only (what `python -m cake_drake.run` imports), `make test` with the
# `test` extra on top (the optional planners, OMPL, Ray, Gymnasium, LeRobot with torch).
# One .venv for both: `make test` after `make run` adds the extras, `make run` after
# `make test` installs nothing.
#
# Which Python makes .venv: PYTHON if you set it, else the newest found of python3.13 and
# python3.12 (on PATH, uv's, pyenv's), then python3. `make test` needs 3.12 or newer
# (Drake 1.58 and LeRobot 0.6 have no wheels for 3.11); `make run` also takes 3.11
# (Debian 12's own, with Drake 1.51). `make test` also makes .venv-oldest, the oldest
# supported pair (Python 3.11, Drake 1.51.1), where a Python 3.11 is found: a test runs
# the main job there.
PYTHON ?=
VENV := .venv
PY := $(VENV)/bin/python
RUN_STAMP := $(VENV)/.installed-run
TEST_STAMP := $(VENV)/.installed-test
SYSTEM_PACKAGES := system-packages.txt
OLDEST := .venv-oldest
OLDEST_DRAKE := 1.51.1

# $(call find_python,MINOR,CANDIDATES): the first of CANDIDATES (default: the newest first,
# as above) that runs and is Python 3.MINOR or newer.
python_ok = import sys; sys.exit(sys.version_info[:2] < (3, $(1)))
define find_python
$(shell for p in $(or $(2),$(PYTHON),python3.13 "$$(uv python find 3.13 2>/dev/null)" \
	  $$(ls -d "$$(pyenv root 2>/dev/null)"/versions/3.13*/bin/python3.13 2>/dev/null | sort -rV 2>/dev/null) \
	  python3.12 "$$(uv python find 3.12 2>/dev/null)" \
	  $$(ls -d "$$(pyenv root 2>/dev/null)"/versions/3.12*/bin/python3.12 2>/dev/null | sort -rV 2>/dev/null) \
	  python3); do \
	[ -n "$$p" ] && "$$p" -c '$(call python_ok,$(1))' 2>/dev/null && { command -v "$$p"; break; }; \
	done)
endef
# The goals that install the test extra need 3.12; `make run` alone takes 3.11.
NEEDS_TEST := $(filter-out run system-packages-run,$(or $(MAKECMDGOALS),run))
MIN_MINOR := $(if $(NEEDS_TEST),12,11)
VENV_PYTHON = $(or $(call find_python,$(MIN_MINOR)),$(error make $(or $(MAKECMDGOALS),run) \
	needs Python 3.$(MIN_MINOR) or newer$(if $(PYTHON), and PYTHON=$(PYTHON) is not,$(strip \
	) and none was found (python3.13$(comma) python3.12$(comma) uv's$(comma) pyenv's$(comma) python3)); \
	get one with: uv python install 3.12 (or: pyenv install 3.12)$(comma) then make \
	$(or $(MAKECMDGOALS),run) again$(if $(PYTHON),, (or name it: PYTHON=/path/to/python3.12))))
comma := ,
# Python 3.11 for the oldest supported pair: on PATH, uv's, pyenv's, or python3.
OLDEST_PYTHON = $(call find_python,11,python3.11 "$$(uv python find 3.11 2>/dev/null)" \
	$$(ls -d "$$(pyenv root 2>/dev/null)"/versions/3.11*/bin/python3.11 2>/dev/null | sort -rV 2>/dev/null) \
	python3)

.PHONY: python run test notebooks lint bench clean venv oldest system-packages-run system-packages-test

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
	$(VENV_PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# The base dependencies: refreshed when pyproject.toml changes. pip leaves installed
# extras alone (it removes nothing and upgrades only what a requirement asks for).
$(RUN_STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install --quiet -e .
	touch $(RUN_STAMP)

# The test extra on top: after the base install (so a changed pyproject.toml refreshes
# the base first, and both stamps are current afterwards).
$(TEST_STAMP): $(RUN_STAMP)
	@$(PY) -c '$(call python_ok,12)' || { echo "error: .venv is $$($(PY) -V 2>&1), and make \
	  test needs Python 3.12 or newer: remove it (make clean), then make test again" >&2; exit 1; }
	$(PY) -m pip install --quiet -e '.[test]' -e plugins/lerobot_env_cake_drake
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

# Before anything is installed: the Python for a new .venv, or the one-line stop.
python:
	@: $(if $(wildcard $(PY)),,$(VENV_PYTHON))

run: python system-packages-run $(BYTECODE)
	$(PY) -m cake_drake.run --mode torque

# The oldest supported pair, for tests/contracts/test_setup.py's run of the main job there: made
# where a Python 3.11 is found (nothing to do elsewhere; the test says it was skipped).
OLDEST_STAMP := $(OLDEST)/.installed-$(OLDEST_DRAKE)
oldest:
	@$(if $(OLDEST_PYTHON),$(MAKE) -s $(OLDEST_STAMP),echo "note: no Python 3.11 here: the \
	  main job is not tested on the oldest supported pair (Python 3.11, Drake $(OLDEST_DRAKE))")

$(OLDEST_STAMP): pyproject.toml
	rm -rf $(OLDEST)
	$(OLDEST_PYTHON) -m venv $(OLDEST)
	$(OLDEST)/bin/python -m pip install --quiet --upgrade pip
	$(OLDEST)/bin/python -m pip install --quiet drake==$(OLDEST_DRAKE) --editable .
	touch $(OLDEST_STAMP)

# The suite on every core (pytest-xdist): first the tests marked `alone`, one at a time
# with nothing beside them, then the rest spread over the cores. Both parts always run;
# make test fails if either failed. PYTEST_ARGS adds options to both (e.g. -k NAME).
JOBS ?= auto
test: python system-packages-test $(TEST_STAMP) $(BYTECODE) oldest
	@status=0; \
	$(PY) -m pytest -m alone $(PYTEST_ARGS) || { r=$$?; [ $$r -eq 5 ] || status=$$r; }; \
	$(PY) -m pytest -n $(JOBS) -m "not alone" $(PYTEST_ARGS) || { r=$$?; [ $$r -eq 5 ] || status=$$r; }; \
	exit $$status

notebooks: system-packages-test $(TEST_STAMP) $(BYTECODE)
	$(PY) notebooks/refresh.py

lint: $(TEST_STAMP) $(BYTECODE)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check . && $(VENV)/bin/lint-imports

# The planning table compares Fast Downward too (the test extra has it).
bench: system-packages-run $(TEST_STAMP) $(BYTECODE)
	$(PY) benchmarks/planning.py
	$(PY) benchmarks/ik.py
	$(PY) benchmarks/run.py
	$(PY) benchmarks/sweep.py models/sweeps/smoke.yaml models/sweeps/kd.yaml

clean:
	rm -rf $(VENV) $(OLDEST) outputs .pytest_cache
