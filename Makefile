# Two commands: `make demo` and `make test`. Both bootstrap .venv on a fresh clone.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint typecheck bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "Python >= 3.11 is required")'
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

demo: $(STAMP)
	$(PY) -m companion replay sitl_configs/scenarios/crossing.toml \
		--out out/crossing.json --plot out/crossing.png

lint: $(STAMP)
	$(VENV)/bin/ruff check protocol companion tests scripts
	$(VENV)/bin/ruff format --check protocol companion tests scripts

typecheck: $(STAMP)
	$(VENV)/bin/mypy --strict protocol companion

test: lint typecheck
	$(VENV)/bin/pytest

bench: $(STAMP)
	$(PY) -m protocol bench crypto

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis out
