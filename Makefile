# Two commands on a fresh machine: `make demo` and `make test`. Both build .venv when missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup test test-fast demo bench clean

setup: $(STAMP)

$(STAMP): setup.py package.xml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,test,bench]'
	touch $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -n 2 -q test

test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -q -m "not slow" test

demo: $(STAMP)
	$(PY) -m ship_ident.demo

clean:
	rm -rf $(VENV) build install log .pytest_cache
