# mechsys — set-up and everyday tasks. Everything installs into a local virtual environment (.venv).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install demo test test-fast check bench docs clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev,docs]"
	# an editable install compiles no bytecode, and where PYTHONDONTWRITEBYTECODE is set every command would compile
	# mechsys's source again (0.25 s); a changed file is compiled afresh, in memory, as usual
	$(BIN)/python -m compileall -q mechsys
	# optional: the Tiny C Compiler builds the steady-motion programs 50 times faster than gcc -O0, the same code
	# (numeric/native.py quick_compiler); installed where Debian's apt-get may run, skipped elsewhere
	@command -v tcc >/dev/null 2>&1 || DEBIAN_FRONTEND=noninteractive timeout 300 apt-get install -y -qq tcc >/dev/null 2>&1 \
		|| (timeout 300 apt-get update -qq >/dev/null 2>&1 \
			&& DEBIAN_FRONTEND=noninteractive timeout 300 apt-get install -y -qq tcc >/dev/null 2>&1) \
		|| echo "note: tcc not installed (optional; 'apt-get install tcc' makes a first equilibria/modes on a constrained model faster)"
	touch $(STAMP)

install: $(STAMP)

## demo: install, then derive, describe, analyse and simulate the bundled centrifuge (Krodkiewski ch. 5)
demo: $(STAMP)
	$(BIN)/mechsys info systems/centrifuge.yaml
	$(BIN)/mechsys derive systems/centrifuge.yaml --check
	$(BIN)/mechsys equilibria systems/centrifuge.yaml
	$(BIN)/mechsys simulate systems/centrifuge.yaml --t-end 60

## test: install, run the textbook checks of every bundled model, then the whole suite (slow tests included)
test: $(STAMP)
	$(BIN)/mechsys check systems/ -f markdown
	$(BIN)/python -m pytest -n 2 -q --durations=25

## test-fast: skip the tests marked slow
test-fast: $(STAMP)
	$(BIN)/python -m pytest -n 2 -q -m "not slow"

## check: run the textbook expectations of every bundled model (docs/check.md); JUnit report in check-report.xml
check: $(STAMP)
	$(BIN)/mechsys check systems/ --junit check-report.xml

## bench: speed benchmarks, reported as ratios against the named baselines
bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,bench]"
	$(BIN)/python benchmarks/derive_chain.py
	$(BIN)/python benchmarks/derive_chain.py --commands --timeout 60
	$(BIN)/python benchmarks/derive_bicycle.py
	$(BIN)/python benchmarks/backends.py
	$(BIN)/python benchmarks/simulate_anchor.py
	$(BIN)/mechsys bench systems/double_pendulum.yaml --t-end 5
	$(BIN)/mechsys bench systems/four_bar.yaml --t-end 2 --methods native,DOP853,Radau
	$(BIN)/mechsys bench systems/centrifuge.yaml --t-end 20
	$(BIN)/mechsys bench tests/data/andrews_squeezer.yaml --t-end 0.03 --methods native,DOP853,Radau --rtols 1e-6,1e-8,1e-10

## docs: the gallery figures from the bundled models, then the MkDocs site in site/ (--strict: a warning or a broken
## link fails); tests/test_docs_examples.py checks every example of the pages
docs: $(STAMP)
	$(BIN)/python docs/hooks/gallery.py $(BIN)/mechsys
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis build site *.egg-info
