# One entry point per job; the README's quick start calls demo and test (docs: the site).
#
# Both run in the project's own virtual environment, .venv, made on first use with
# `python3 -m venv`: a stock Debian/Ubuntu Python refuses `pip install` outside a
# virtual environment (PEP 668, "externally-managed-environment"). Inside an active
# virtual environment ($VIRTUAL_ENV set) that one is used instead, and none is made.
# The install is redone when pyproject.toml changes (a stamp file in the environment).
PY ?= python3
ifdef VIRTUAL_ENV
VENV := $(VIRTUAL_ENV)
else
VENV := .venv
endif
VPY := $(VENV)/bin/python
PIP := $(VPY) -m pip install -q --disable-pip-version-check

.PHONY: demo test check install dev lint types unit venv docs

demo: install
	$(VPY) -m statectl demo

test: dev check

check: lint types unit

venv: $(VPY)

install: $(VENV)/.statectl-install

dev: $(VENV)/.statectl-dev

ifdef VIRTUAL_ENV
$(VPY):
	@echo "make: the active virtual environment $(VENV) has no bin/python; deactivate it" >&2
	@exit 1
else
# A venv that failed half-way (no ensurepip: Debian's python3-venv missing) is removed,
# so the next make starts over instead of using it.
$(VPY):
	@$(PY) -m venv $(VENV) || { rm -rf $(VENV); \
	  echo "make: '$(PY) -m venv $(VENV)' failed; on Debian/Ubuntu: apt-get install python3-venv" >&2; \
	  exit 1; }
endif

$(VENV)/.statectl-install: pyproject.toml | $(VPY)
	$(PIP) -e .
	@touch $@

$(VENV)/.statectl-dev: pyproject.toml | $(VPY)
	$(PIP) -e '.[dev]'
	@touch $@ $(VENV)/.statectl-install

# The docs site (mkdocs.yml): built into site/ with --strict; a broken link or anchor fails.
docs: dev
	NO_MKDOCS_2_WARNING=1 $(VPY) -m mkdocs build --strict

lint:
	$(VPY) -m ruff check .
	$(VPY) -m ruff format --check .

types:
	$(VPY) -m mypy

unit:
	$(VPY) -m pytest
