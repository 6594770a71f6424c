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
	$(PY) -m ship_ident.online.warmup
	touch $(STAMP)

lint: $(STAMP)
	$(PY) -m ruff check ship_ident test
	$(PY) -m ruff format --check ship_ident test

# The tests that start ROS nodes (marker `node`) wait on DDS and on their nodes' clocks, leaving most
# of the CPU idle: they run in a pytest of their own beside the others, which run at a lower
# priority (nice) so that the nodes keep their pace. The node tests' summary follows the others'.
# Each process of a test run (pytest workers, nodes, command-line subprocesses) reads the compiled and
# assertion-rewritten modules the first one left in __pycache__ instead of compiling them again, also
# where the environment sets PYTHONDONTWRITEBYTECODE (a test collection costs 1.5 s of CPU less).
test test-fast: export PYTHONDONTWRITEBYTECODE :=

test: lint
	@log=$$(mktemp); $(PY) -m pytest -n 2 --maxschedchunk 1 -q -rs -p no:cacheprovider -m node test >$$log 2>&1 & \
	node_tests=$$!; trap 'kill $$node_tests 2>/dev/null' INT TERM; \
	nice -n 10 $(PY) -m pytest -n 2 --maxschedchunk 1 -q -rs -m "not node" test; others=$$?; \
	wait $$node_tests; nodes=$$?; \
	echo "--- the tests that start ROS nodes (run beside the others):"; cat $$log; rm -f $$log; \
	[ $$others -eq 0 ] && [ $$nodes -eq 0 ]

test-fast: lint
	$(PY) -m pytest -n 2 --maxschedchunk 1 -q -rs -m "not slow" test

demo: $(STAMP)
	$(PY) -m ship_ident.ros.demo

clean:
	rm -rf $(VENV) build install log .pytest_cache
