# Two set-up commands for a fresh machine:  make demo   |   make test
PY ?= python3
VENV ?= .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-socketcan socketcan-tests lint venv native lock lock-add clean

#: the lock files: exact versions with hashes, resolved by uv for Python 3.11 on Linux x86_64
#: (CI's platform). dev.lock: the base + every extra make and CI install; base.lock: the daemon
#: and the emulator alone (a bench PC), the same versions. `make lock` is the only way they move.
LOCK := requirements/dev.lock
BASE_LOCK := requirements/base.lock
EXTRAS := test plot monitor campaign identify mf4 fmu
TEST_WORKERS ?= 2
UV_VERSION := 0.13.9
UV_VENV := .venv-uv
LOCK_PYTHON := 3.11

$(STAMP): pyproject.toml $(LOCK)
	$(PY) -m venv $(VENV)
	$(VPY) -m pip install --quiet --require-hashes --no-deps -r $(LOCK)
	$(VPY) -m pip install --quiet --no-deps --no-build-isolation -e .
	$(VPY) -m pip check
	$(VPY) -m ehpss_hil.nativebuild
	touch $(STAMP)

venv: $(STAMP)

## compile the per-sample code (ehpss_hil/control/, the nonlinear plant) with mypyc again: after
## editing one of those modules they run from source (slower, and stderr says so) until this
## runs; `$(VPY) -m ehpss_hil.nativebuild status|clean` shows or removes the build
native: $(STAMP)
	$(VPY) -m ehpss_hil.nativebuild

## refresh the lock files to the newest releases pyproject.toml allows, rebuild .venv from them
## and run the test suite on them: how a new numpy/scipy/cantools enters (commit the locks only
## when it is green)
lock:
	test -x $(UV_VENV)/bin/uv || { $(PY) -m venv $(UV_VENV) && $(UV_VENV)/bin/pip install --quiet uv==$(UV_VERSION); }
	$(UV_VENV)/bin/uv pip compile --quiet --upgrade --generate-hashes --python-version $(LOCK_PYTHON) \
		pyproject.toml requirements/build.in $(addprefix --extra ,$(EXTRAS)) -o $(LOCK)
	$(UV_VENV)/bin/uv pip compile --quiet --generate-hashes --python-version $(LOCK_PYTHON) \
		pyproject.toml requirements/build.in -c $(LOCK) -o $(BASE_LOCK)
	rm -rf $(VENV)
	$(MAKE) test

## add what pyproject.toml newly asks for (a new extra, a new dependency) to the lock files
## without moving any package already pinned (no --upgrade: uv keeps the pins in the output
## file); check with `git diff requirements/` that only new packages appear
lock-add:
	test -x $(UV_VENV)/bin/uv || { $(PY) -m venv $(UV_VENV) && $(UV_VENV)/bin/pip install --quiet uv==$(UV_VERSION); }
	$(UV_VENV)/bin/uv pip compile --quiet --generate-hashes --python-version $(LOCK_PYTHON) \
		pyproject.toml requirements/build.in $(addprefix --extra ,$(EXTRAS)) -o $(LOCK)
	$(UV_VENV)/bin/uv pip compile --quiet --generate-hashes --python-version $(LOCK_PYTHON) \
		pyproject.toml requirements/build.in -c $(LOCK) -o $(BASE_LOCK)

## the main job: emulator + controller, a fault scenario, log, metrics and figures
demo: $(STAMP)
	$(VENV)/bin/ehpss-hil demo

## the test suite (host); SocketCAN tests skip here unless AF_CAN works. Two passes: every test
## not marked `alone` on TEST_WORKERS pytest-xdist workers (2: the cores of the CI host; more would
## put more real-time processes on the host than the tests that time them judge; TEST_WORKERS=0
## runs them in one process), then the `alone` ones one after the other on an otherwise idle host
## (only their files are collected). Within one pass the browser tests take one bench at a time
## (tests/_monitor_page.py).
ALONE_TESTS := $(shell grep -l "pytest.mark.alone" tests/test_*.py)
test: $(STAMP)
	$(VPY) -m pytest -q -n $(TEST_WORKERS) -m "not alone"
	$(VPY) -m pytest -q -m alone $(ALONE_TESTS)

## lint, format and types (CI runs these after make test)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VPY) -m mypy ehpss_hil firmware_sim tests

## the SocketCAN suite (needs vcan0: natively, or inside ../shared/tools/vcan-vm/run); only the
## files that hold such tests are collected (collecting all of tests/ took ~5 min inside the VM),
## without hypothesis' pytest plugin (none of them uses it; importing it took half the
## collection: 7.6 -> 3.9 s on the host, ~10x that inside the VM)
SOCKETCAN_TESTS := $(shell grep -l "pytest.mark.socketcan" tests/*.py)
SOCKETCAN_PYTEST := -m pytest -q -m socketcan -p no:hypothesispytest --durations=10
test-socketcan: $(STAMP)
	$(VPY) $(SOCKETCAN_PYTEST) $(SOCKETCAN_TESTS)

## print the SocketCAN suite's pytest arguments and files, nothing when no test is marked
## socketcan (.ci/run runs them inside the VM)
socketcan-tests:
	@test -z "$(SOCKETCAN_TESTS)" || echo $(SOCKETCAN_PYTEST) $(SOCKETCAN_TESTS)

clean:
	test ! -x $(VPY) || $(VPY) -m ehpss_hil.nativebuild clean
	rm -rf $(VENV) $(UV_VENV) out runs .pytest_cache
