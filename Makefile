# Two commands on a fresh machine: `make demo` and `make test`. Both build .venv when missing.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup lint test test-fast demo bench clean

setup: $(STAMP)

$(STAMP): setup.py package.xml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,test,bench]'
	@command -v chromium >/dev/null 2>&1 || { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 \
	  && apt-get update -qq && apt-get install -y -qq chromium >/dev/null; } \
	  || echo "note: chromium not installed; the report rendering test will skip"
	touch $(STAMP)

lint: $(STAMP)
	$(PY) -m ruff check ship_ident test
	$(PY) -m ruff format --check ship_ident test

test: lint
	$(PY) -m pytest -n 2 --maxschedchunk 1 -q -rs test

test-fast: lint
	$(PY) -m pytest -n 2 --maxschedchunk 1 -q -rs -m "not slow" test

demo: $(STAMP)
	$(PY) -m ship_ident.demo

clean:
	rm -rf $(VENV) build install log .pytest_cache
