# Two set-up commands for a fresh machine:  make demo   |   make test
PY ?= python3
VENV ?= .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test test-socketcan lint venv clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip
	$(VPY) -m pip install --quiet -e '.[test,plot,monitor,campaign]'
	touch $(STAMP)

venv: $(STAMP)

## the main job: emulator + controller, a fault scenario, log, metrics and figures
demo: $(STAMP)
	$(VENV)/bin/ehpss-hil demo

## the test suite (host); SocketCAN tests skip here unless AF_CAN works
test: $(STAMP)
	$(VPY) -m pytest -q

## lint, format and types (CI runs these after make test)
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VPY) -m mypy ehpss_hil firmware_sim tests

## the SocketCAN suite (needs vcan0: natively, or inside ../shared/tools/vcan-vm/run)
test-socketcan: $(STAMP)
	$(VPY) -m pytest -q -m socketcan tests/

clean:
	rm -rf $(VENV) out runs .pytest_cache
