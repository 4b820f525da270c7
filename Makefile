# cdw-twin: two commands for a fresh Debian machine with python3.
#   make demo   set up (venv, pinned packages, message build, FMU build) and run the main job
#   make test   same set-up, then ruff, mypy and the whole test suite
# Every set-up step is stamped, so a second call skips what is done.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
CLI    := $(VENV)/bin/cdw-twin
STAMPS := $(VENV)/.stamps

FMU_SOURCES := $(wildcard fmus/framework/* fmus/belt_drive/* fmus/build.py)
MSG_SOURCES := $(wildcard interfaces/cdw_interfaces/msg/*.msg interfaces/cdw_interfaces/CMakeLists.txt interfaces/cdw_interfaces/package.xml interfaces/tf2_msgs/msg/*.msg interfaces/tf2_msgs/CMakeLists.txt interfaces/tf2_msgs/package.xml interfaces/build_interfaces.py interfaces/cmake/pypi_wheel_fixups.cmake)

.PHONY: setup demo test lint typecheck pytest clean

setup: $(STAMPS)/deps $(STAMPS)/fmus $(STAMPS)/msgs

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMPS)/deps: pyproject.toml constraints.txt | $(PY)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet -c constraints.txt -e '.[dev]'
	@mkdir -p $(STAMPS) && touch $@

$(STAMPS)/fmus: $(STAMPS)/deps $(FMU_SOURCES)
	$(CLI) fmu build
	@touch $@

$(STAMPS)/msgs: $(STAMPS)/deps $(MSG_SOURCES)
	$(PY) interfaces/build_interfaces.py
	@touch $@

demo: setup
	$(CLI) demo

lint: $(STAMPS)/deps
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

typecheck: $(STAMPS)/deps
	$(VENV)/bin/mypy

pytest: setup
	$(VENV)/bin/pytest -q -n 2 --dist loadfile

# ruff and mypy run beside the FMU and message builds and then the suite (-j: mypy is one core
# for ~20 s; the builds and the suite's workers also wait on subprocesses and the wall clock);
# their lines are not mixed. mypy needs no built message (ignore_missing_imports).
test: $(STAMPS)/deps
	$(MAKE) --no-print-directory -j3 --output-sync=line lint typecheck pytest

clean:
	rm -rf fmus/build interfaces/build $(STAMPS)
