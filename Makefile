# Two commands: `make demo` and `make test`. Both bootstrap .venv on a fresh clone.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo demo-px4 test lint typecheck bench clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "Python >= 3.11 is required")'
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

demo: $(STAMP)
	@mkdir -p out
	$(PY) -m companion replay sitl_configs/scenarios/crossing.toml \
		--out out/crossing.json --plot out/crossing.png --export out/crossing

# The crossing on two PX4 SITL (SIH) vehicles: make demo-px4 PX4_SITL=/path/to/px4-sitl
demo-px4: $(STAMP)
	@test -n "$(PX4_SITL)" || { echo "error: set PX4_SITL to a PX4 SITL build (bin/px4, etc/), e.g. make demo-px4 PX4_SITL=/path/to/px4-sitl" >&2; exit 2; }
	@mkdir -p out
	$(PY) -m companion replay sitl_configs/scenarios/crossing.toml --px4 "$(PX4_SITL)" \
		--out out/crossing-px4.json --plot out/crossing-px4.png

lint: $(STAMP)
	$(VENV)/bin/ruff check protocol companion tests scripts
	$(VENV)/bin/ruff format --check protocol companion tests scripts

typecheck: $(STAMP)
	$(VENV)/bin/mypy --strict protocol companion tests scripts

# Two workers: the real-time tests (replays, PX4 SITL; xdist_group "realtime") run one at a
# time on one of them, everything else shares the other.
test: lint typecheck
	$(VENV)/bin/pytest -n 2 --dist loadgroup

bench: $(STAMP)
	$(PY) -m protocol bench crypto

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis out
