# Every target creates .venv idempotently; torch is pinned first so no CUDA build is pulled.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.docs-installed
export OMP_NUM_THREADS ?= 1

.PHONY: install demo test test-slow lint docs docs-serve clean

$(PY):
	python3 -m venv $(VENV)

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q torch==2.13.0
	$(PY) -m pip install -q -e ".[dev,ray]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m ovon.cli.main demo

test: $(STAMP)
	$(PY) -m pytest -q -x --durations=15

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow --durations=0

lint: $(STAMP)
	$(VENV)/bin/ruff check ovon tests benchmarks clients experiments
	$(VENV)/bin/ruff format --check ovon tests benchmarks clients experiments

# The docs tools (the `docs` extra) install once; the site builds offline into site/ (mkdocs.yml).
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install -q -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

docs-serve: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs serve --strict

clean:
	rm -rf $(VENV) build *.egg-info
