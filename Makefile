# SkyHelm: `make run` and `make test` do all set-up on a fresh machine.
VENV    ?= .venv
PYTHON  ?= python3
PY      := $(VENV)/bin/python
PIP     := $(PY) -m pip
STAMP   := $(VENV)/.installed
TSTAMP  := $(VENV)/.installed-test
ARGS    ?=

.PHONY: run test lint bench sim chromium clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip

$(STAMP): pyproject.toml | $(PY)
	$(PIP) install -q -e .
	touch $@

$(TSTAMP): pyproject.toml $(STAMP)
	$(PIP) install -q -e '.[test]'
	touch $@

## Start the server with the embedded simulated vehicle and print the URL.
run: $(STAMP)
	$(VENV)/bin/skyhelm serve $(ARGS)

## Run the simulated vehicle alone, like PX4 SITL.
sim: $(STAMP)
	$(VENV)/bin/skyhelm sim $(ARGS)

## Debian's chromium for the browser tests (installed when missing and running as root).
chromium:
	@if ! command -v chromium >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver; \
	  else echo "chromium not installed and not root: browser tests will be skipped"; fi; \
	fi

lint: $(TSTAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy --strict server sim
	$(VENV)/bin/lint-imports

test: $(TSTAMP) chromium lint
	$(VENV)/bin/pytest -q -p no:cacheprovider

bench: $(TSTAMP)
	$(PY) -m bench.run_all

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
