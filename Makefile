# SkyHelm: `make run` and `make test` do all set-up on a fresh machine.
VENV    ?= .venv
PYTHON  ?= python3
PY      := $(VENV)/bin/python
PIP     := $(PY) -m pip
STAMP   := $(VENV)/.installed
TSTAMP  := $(VENV)/.installed-test
BSTAMP  := $(VENV)/.installed-bench
ARGS    ?=

.PHONY: run test test-chain test-px4 lint audit bench soak sim chromium clean

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip

# The Python client is a distribution of its own (clients/python/), with the wire format
# (wire/skyhelm_wire) inside it; installed from its path in the same pip call, never from
# an index. A venv made when the wire was a distribution of its own drops that one first.
# pip compiles what it installs one file at a time; compileall does it on every core after
# (a fresh venv with the test tools, two runs each: 49-51 s before, 37-45 s so). Files that
# do not compile (some packages ship Python 2 examples) are left out, as pip leaves them.
# So are pymavlink's dialects that nothing here imports (9 of its 2 MB modules in each of
# MAVLink 1 and 2, 5 of the 24 CPU-s of compiling the venv); one imported compiles then.
UNUSED_DIALECTS := pymavlink/dialects/v[12]0/(ASLUAV|AVSSUAS|cubepilot|matrixpilot|paparazzi|python_array_test|storm32|uAvionix|ualberta)\.py
COMPILE := $(PY) -m compileall -q -q -j 0 -x '$(UNUSED_DIALECTS)' $(VENV)/lib >/dev/null || true

$(STAMP): pyproject.toml clients/python/pyproject.toml | $(PY)
	$(PIP) uninstall -q -y skyhelm-wire 2>/dev/null || true
	$(PIP) install -q --no-compile -e ./clients/python -e .
	$(COMPILE)
	touch $@

# One pip call for the product and its test tools: a second would resolve everything again.
$(TSTAMP): pyproject.toml clients/python/pyproject.toml | $(PY)
	$(PIP) uninstall -q -y skyhelm-wire 2>/dev/null || true
	$(PIP) install -q --no-compile -e ./clients/python -e '.[test]'
	$(COMPILE)
	touch $(STAMP) $@

$(BSTAMP): pyproject.toml $(TSTAMP)
	$(PIP) install -q -e ./clients/python -e '.[test,bench]'
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
	$(VENV)/bin/mypy --strict server sim wire/skyhelm_wire clients/python/skyhelm_client
	$(VENV)/bin/lint-imports

## pip-audit over the packages installed in $(VENV) (tools/audit.py): known vulnerabilities
## fail; when the vulnerability service cannot be reached, or answers for none of them, a
## banner says the dependencies were NOT audited and the run goes on, unless AUDIT_STRICT=1
## (CI), which fails it.
audit: $(TSTAMP)
	$(PY) -m tools.audit

## Four workers on two cores: most tests wait on a real-time simulated vehicle, not on a core;
## the browser tests run in two groups, the longest modules first (tests/conftest.py). A fresh
## clone's whole `make test` on a quiet 2-core machine: 712-785 s with three, 630-642 s with
## four (the machine's cores 75 % busy with three, 83 % with four). Earlier, on a machine three
## times slower per core than usual, four took as long as three with more failures (vehicles
## and servers starved of a core); since then the suite waits on what it tests, not on time, and
## holds beside two busy loops. Five took a tenth off a quiet run on a fast machine, but beside
## two busy loops the vehicles then missed their answers; a third browser group made the run
## slower. TEST_WORKERS=0 runs everything in one process.
TEST_WORKERS ?= 4

## Set-up runs two at a time: the packages beside Debian's chromium. The linters and the audit
## (a few seconds of CPU, the rest waiting on the vulnerability service) then run beside the
## tests, their output shown after them; any of the three failing fails the target.
## The project's own sources are compiled first, on every core: the suite starts well over a
## hundred servers and simulated vehicles, and where PYTHONDONTWRITEBYTECODE is set (as in
## many CI images) each of them compiled every module it imports again (`skyhelm serve` to
## its URL: 4.0 CPU-s so, 3.4 compiled). A compiled file older than its source is not used.
## pytest keeps the test modules it rewrites (for its assertions) in compiled files of its own,
## which it writes only where PYTHONDONTWRITEBYTECODE is unset: each worker collects the whole
## suite, 22.5 CPU-s rewriting them all and 10.5 CPU-s reading them kept (two runs each).
SOURCES := server sim wire clients/python tools tests bench
test:
	@$(MAKE) --no-print-directory -j2 --output-sync=target $(TSTAMP) chromium
	@$(PY) -m compileall -q -q -j 0 $(SOURCES) >/dev/null || true
	@$(MAKE) --no-print-directory -j2 --output-sync=target lint audit >$(VENV)/checks.log 2>&1 & \
	checks=$$!; \
	env -u PYTHONDONTWRITEBYTECODE $(VENV)/bin/pytest -q -p no:cacheprovider -n $(TEST_WORKERS); \
	tests=$$?; \
	wait $$checks; checked=$$?; cat $(VENV)/checks.log; \
	test $$tests = 0 && test $$checked = 0

## The whole chain of documented flows (README and docs/api.md curl sessions, the examples,
## a page flight, scripts killed half-way) on the simulated quad at real speed, default
## settings (7–10 min; `make test` runs a shorter chain at 8x).
test-chain: $(TSTAMP) chromium
	$(VENV)/bin/pytest -q -p no:cacheprovider -m chain -rs tests/browser/test_flow_chain_full.py

## The REST flight and the chain of documented flows against real PX4 v1.16 SITL (the kit of shared/px4-sitl, built into
## SKYHELM_PX4_SITL_DIR or /root/px4sitl); skipped with a message when there is no build.
## SKYHELM_PX4_INSTANCE=N picks the instance (its ports follow the kit's layout);
## SKYHELM_PX4_SOAK_MINUTES=10 adds the hover through 20 % loss (tests/px4/test_px4_radio_loss.py).
test-px4: $(TSTAMP)
	@dir="$${SKYHELM_PX4_SITL_DIR:-/root/px4sitl}"; \
	if [ ! -x "$$dir/build/px4_sitl_default/bin/px4" ]; then \
	  echo "test-px4: skipped, no PX4 SITL build in $$dir (set SKYHELM_PX4_SITL_DIR)"; \
	else \
	  SKYHELM_PX4_SITL_DIR="$$dir" $(VENV)/bin/pytest -q -p no:cacheprovider -m px4 -rs tests/px4; \
	fi

## Every benchmark at its default size (~9 min on 2 cores, within a 15 min budget; each prints
## its time), then docs/PERFORMANCE.md and its figures (docs/img/perf/). ARGS="--quick" for a smoke run,
## ARGS="--only api_load,signing" for some; bench/run_all.py --help for the rest.
bench: $(BSTAMP) chromium
	$(PY) -m bench.run_all $(ARGS)

## 30 minutes hovering in OFFBOARD on the simulated vehicle (real time) through 20 % loss
## each way, after 20 HEARTBEAT-only drops of 3.6 s: false link-lost verdicts, failsafes,
## commands answered and true or 504, setpoints received against sent
## (bench/results/radio_soak.json). ARGS="--minutes 5 --burst 5" for others.
soak: $(BSTAMP)
	$(PY) -m bench.radio_soak --heartbeat-drops 20 $(ARGS)

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
