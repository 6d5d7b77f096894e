# One entry point per job; the README's quick start calls these two.
PY ?= python3

.PHONY: demo test check install dev lint types unit

demo: install
	$(PY) -m statectl demo

test: dev check

check: lint types unit

install:
	$(PY) -m pip install -q --disable-pip-version-check -e .

dev:
	$(PY) -m pip install -q --disable-pip-version-check -e '.[dev]'

lint:
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

types:
	$(PY) -m mypy

unit:
	$(PY) -m pytest
