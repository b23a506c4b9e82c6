# The two commands of the README: `make run` and `make test`. Each sets up what it needs first.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SYSTAMP := $(VENV)/.system-packages

.PHONY: run test lint setup clean-venv

run: $(STAMP)
	bash scripts/run_studio.sh

test: $(STAMP)
	$(VENV)/bin/ruff check app render models tests scripts benchmarks
	$(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check app render models tests scripts benchmarks

setup: $(STAMP)

$(SYSTAMP): scripts/setup_system.sh
	bash scripts/setup_system.sh
	mkdir -p $(VENV) && touch $@

$(STAMP): pyproject.toml scripts/setup_python.sh $(SYSTAMP)
	bash scripts/setup_python.sh $(VENV)
	touch $@

clean-venv:
	rm -rf $(VENV)
