# The two commands of the README: `make run` and `make test` (plus `make bench`).
# Both create .venv and install vasim into it on first use; nothing else is downloaded.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
# `make run` installs the core only; `make test` (and lint, bench) what the tests need: the
# test runners, the developer tools and the cluster (Ray) and parquet (pyarrow) extras.
CORE_STAMP := $(VENV)/.installed-core
STAMP := $(VENV)/.installed
FULL_EXTRAS := test,dev,cluster,parquet

.PHONY: install install-core run test check bench lint clean kernels-mrcp kernels-physics

install: $(STAMP)

install-core: $(CORE_STAMP)

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (vasim needs Python 3.11)"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# Python caches each module's bytecode when it first imports it; with PYTHONDONTWRITEBYTECODE
# set (some shells and containers set it) every process compiles every module it imports
# again: ~6 s of the ~17 s of CPU a test worker's collection takes. So no make step sees it,
# and pip does not byte-compile the ~1.5 GB it installs (`--no-compile`): most of it (Ray's
# dashboard, serve, tune ...) is never imported, and compiling it all took 49 of `make
# test`'s 89 s of install on a 2-core machine (40 s without, 2026-12-02).
unexport PYTHONDONTWRITEBYTECODE
PIP_INSTALL := $(PY) -m pip install --quiet --no-compile

$(CORE_STAMP): pyproject.toml | $(PY)
	$(PIP_INSTALL) -e .
	touch $(CORE_STAMP)

$(STAMP): pyproject.toml | $(PY)
	$(PIP_INSTALL) -e '.[$(FULL_EXTRAS)]'
	touch $(STAMP) $(CORE_STAMP)

run: install-core
	$(VENV)/bin/vasim serve --host 127.0.0.1 --port 8080 --db study.sqlite

PYTEST := $(PY) -m pytest

# The whole suite (CI): lint beside `kernels-*` (below); then in parallel (pytest-xdist, one
# worker per core, a test file per worker) all but the browser and Ray tests; then those two
# groups one test at a time (each paces real time or starts process trees sized to the
# machine's cores); then every benchmark in its seconds-long smoke mode. Each phase prints
# its slowest 20 tests. (Running the Ray tests and the benchmarks beside the browser tests
# would gain nothing: Chromium's software drawing keeps both cores ~95 % busy. Measured again
# on 2026-12-02, after the pages stopped drawing viser's environment map: the browser tests
# beside the Ray tests took 430 s, one at a time 463 s, with the CPU 97.7 % busy.)
test: install
	.ci/ensure-chromium
	$(MAKE) --no-print-directory -j3 -Otarget lint kernels-mrcp kernels-physics
	$(PYTEST) -n auto --dist loadfile -m "not browser and not cluster" --durations=20
	$(PYTEST) -m "browser or cluster" --durations=20
	$(PY) -m bench --smoke

# Compiles and caches the numba kernels once, by running a second of the MRCP's eight-robot
# demo (~95 s of CPU when cold) and of a headless trial (the physics, contact and servo
# kernels, ~25 s). Without it the parallel test workers, and the CLI subprocesses tests
# start, each compiled the same kernels again: phase 2 on a clean clone took 836 s, and
# 680 s with the kernels cached (2026-12-01). A kernel these miss is compiled by the first
# test that needs it, as before.
kernels-mrcp: install
	$(VENV)/bin/vasim mrcp run eight_robots --coarse --duration 1 > /dev/null
	@echo "MRCP kernels compiled and cached"

kernels-physics: install
	$(VENV)/bin/vasim trial --max-time 1 > /dev/null
	@echo "physics kernels compiled and cached"

# A developer's quick loop (a few minutes): no slow, browser or Ray tests, in parallel.
check: install
	$(PYTEST) -n auto --dist loadfile -m "not slow and not browser and not cluster"

bench: install
	$(PY) -m bench

lint: install
	$(VENV)/bin/ruff check vasim tests bench
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
