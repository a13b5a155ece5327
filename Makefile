# mechsys — set-up and everyday tasks. Everything installs into a local virtual environment (.venv).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install demo test test-fast bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

## demo: install, then derive, describe and analyse the bundled centrifuge (Krodkiewski ch. 5)
demo: $(STAMP)
	$(BIN)/mechsys info systems/centrifuge.yaml
	$(BIN)/mechsys derive systems/centrifuge.yaml --check
	$(BIN)/mechsys equilibria systems/centrifuge.yaml

## test: install, then run the whole suite (slow tests included, as in CI)
test: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q

## test-fast: skip the tests marked slow
test-fast: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q -m "not slow"

## bench: speed benchmarks, reported as ratios against the named baselines
bench: $(STAMP)
	$(BIN)/python benchmarks/derive_chain.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis build *.egg-info
