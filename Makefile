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

.PHONY: install install-core run test bench lint clean

install: $(STAMP)

install-core: $(CORE_STAMP)

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "error: $(PYTHON) not found (vasim needs Python 3.11)"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(CORE_STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e .
	touch $(CORE_STAMP)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet -e '.[$(FULL_EXTRAS)]'
	touch $(STAMP) $(CORE_STAMP)

run: install-core
	$(VENV)/bin/vasim serve --host 127.0.0.1 --port 8080 --db study.sqlite

test: install
	.ci/ensure-chromium
	$(VENV)/bin/ruff check vasim tests bench
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports
	$(PY) -m pytest

bench: install
	$(PY) -m bench

lint: install
	$(VENV)/bin/ruff check vasim tests bench
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
