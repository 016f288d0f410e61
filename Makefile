# `make test` and `make demo` build .venv from nothing: torch's CPU wheel first, then the package with every extra.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: test test-slow test-versions lint demo docs install clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[all]"
	touch $(STAMP)

# The default suite leaves out the tests marked slow (whole learning runs, the wheel, the docs build, the benchmarks'
# end-to-end runs, distributed and killed runs: pyproject.toml's addopts); `make test-slow` runs them, and .ci/run runs both.
test: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadfile -q

test-slow: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadfile -q -m slow

# Models must move between Python versions: the save/load tests again under each of OTHER_PYTHONS (interpreters, by
# name or path; .ci/run passes the oldest supported Python and the newest installed), each in its own venv
# (.venv-<interpreter name>) holding the package and its test tools. Each reads the model files the others wrote
# (tests/data).
OTHER_PYTHONS ?= python3.10 python3.13
VERSION_TESTS := tests/test_cross_version.py tests/test_save_load.py tests/test_corrupt_files.py tests/test_sb3_contract.py

test-versions:
	@for python in $(OTHER_PYTHONS); do \
	  venv=.venv-$$(basename $$python); \
	  if [ ! -f $$venv/.installed ] || [ pyproject.toml -nt $$venv/.installed ]; then \
	    $$python -m venv $$venv && $$venv/bin/pip install --quiet --upgrade pip \
	      && $$venv/bin/pip install --quiet torch==2.13.0 && $$venv/bin/pip install --quiet -e ".[dev]" \
	      && touch $$venv/.installed || exit 1; \
	  fi; \
	  echo "$$($$venv/bin/python --version): $(VERSION_TESTS)"; \
	  $$venv/bin/python -m pytest -n 2 --dist loadfile -q $(VERSION_TESTS) || exit 1; \
	done

# ruff's lint and format check (configured in pyproject.toml); `ruff format .` and `ruff check --fix .` mend.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The main job in about a minute on 2 idle cores, 2-3 on busy ones (after make test built the venv): Sarsa(lambda)
# and ER-sigma on the simplest walker, 5 seeds (the fewest with which a side of a finding can get a verdict,
# sb3_er.experiments.findings; every run is judged, those whose values leave the possible returns too, so a demo
# finding with 5 seeds may still be inconclusive), 2500 s of learning each (half the thesis's 5000 s; whole-episode replay makes an ER-sigma run
# take 8-11 s against Sarsa(lambda)'s 1-2 s).
demo: $(STAMP)
	$(BIN)/sb3-er reproduce walker --seeds 5 --algos sarsa_lambda er_sigma --budget 2500 --out results/demo

# The documentation, warnings as errors: docs/_build/html/index.html.
docs: $(STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html

# Removes the venv, caches, build files and what the demo writes; the committed measurements in results/measured/ stay.
clean:
	rm -rf $(VENV) .venv-* .pytest_cache .hypothesis *.egg-info build dist docs/_build docs/results
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
	find results -mindepth 1 -maxdepth 1 ! -name measured -exec rm -rf {} + 2>/dev/null || true
