# Two commands set everything up on a fresh machine (Python >= 3.10 and a C compiler):
#   make demo   -- venv, install, generate the double pendulum and run its scene: out/dp_free.{csv,npz,png,gif,html}
#   make test   -- venv, install, run the test suite
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: demo test install bench clean

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

test: install
	$(BIN)/python -m pytest -q

bench: install
	$(BIN)/python -m pip install --quiet -e '.[bench]'
	$(BIN)/python bench/codegen_scaling.py --quick

clean:
	rm -rf generated/*/ out
