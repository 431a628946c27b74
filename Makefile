# Two entry points for a fresh clone (see README):
#   make train   - set up .venv and run the main job (taskforge train curricula/pick_place.yaml)
#   make test    - set up .venv and run the test suite
PYTHON ?= python3
VENV   ?= .venv
CURRICULUM ?= curricula/pick_place.yaml
ARGS ?=

$(VENV)/.installed: pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --upgrade pip
	$(VENV)/bin/pip install --quiet -c constraints.txt -e '.[test,ray]'
	touch $@

setup: $(VENV)/.installed

train: setup
	$(VENV)/bin/taskforge train $(CURRICULUM) $(ARGS)

test: setup
	$(VENV)/bin/ruff check taskforge tests benchmarks
	$(VENV)/bin/pytest -q

.PHONY: setup train test
