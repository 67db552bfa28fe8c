# Two commands set everything up on a fresh machine (Python >= 3.10 and a C compiler):
#   make demo   -- venv, install, generate the double pendulum and run its scene: out/dp_free.{csv,npz,png,gif,html}
#   make test   -- venv, install, run the everyday subset of the tests (not those marked slow)
# and what CI runs:
#   make test-all -- every test, the slow ones too (bash .ci/run: lint, docs, then this);
#                    make test-collections checks every robot of the collections
#   make lint     -- ruff (configured in pyproject.toml)
# and the documentation:
#   make docs   -- the docs extra; docs/ and the API reference as HTML, warnings as errors
#                  -> docs/_build/html/index.html (readable offline)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: demo test test-all test-collections lint install bench docs clean

$(BIN)/activate:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml $(BIN)/activate
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

install: $(VENV)/.installed

demo: install
	$(BIN)/modelgen generate models/double_pendulum.yaml
	$(BIN)/modelgen simulate models/scenes/dp_free.yaml -o out --animate

# the everyday subset: the tests marked slow (minutes of builds: every robot of
# example-robot-data, the largest cross-checks) are left to test-all
test: install
	$(BIN)/python -m pytest -q -m 'not slow'

test-all: install
	$(BIN)/python -m pytest -q

# every robot of example-robot-data and every model of MuJoCo's suites (test-all
# runs every fourth of them): over a hundred builds
test-collections: install
	MODELGEN_COLLECTION=all $(BIN)/python -m pytest -q tests/test_urdf_robots.py tests/test_mjcf.py

lint: install
	$(BIN)/python -c 'import ruff' 2>/dev/null || $(BIN)/python -m pip install --quiet -e '.[lint]'
	$(BIN)/python -m ruff check .

# -E -a: a fresh build every time, so a warning in an unchanged page is not
# hidden by the cache of the previous build
docs: install
	$(BIN)/python -c 'import sphinx, myst_parser' 2>/dev/null \
		|| $(BIN)/python -m pip install --quiet -e '.[docs]'
	$(BIN)/python -m sphinx -E -a -W --keep-going -q -b html docs docs/_build/html

bench: install
	$(BIN)/python -m pip install --quiet -e '.[bench]'
	$(BIN)/python bench/codegen_scaling.py --quick

clean:
	rm -rf generated/*/ out docs/_build
