# The two commands of the README: `make run` and `make test`. Each sets up what it needs first.
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SYSTAMP := $(VENV)/.system-packages

.PHONY: run test lint setup native clean-venv
# The C compiler for the primitives' march (models/avatars/primitives/native.py): $(CC), else gcc, else clang.
CC_FOUND := $(or $(shell command -v $(CC) 2>/dev/null),$(shell command -v gcc 2>/dev/null),$(shell command -v clang 2>/dev/null))

run: $(STAMP) native
	bash scripts/run_studio.sh

test: $(STAMP) native
	$(VENV)/bin/ruff check app render models tests scripts benchmarks
	$(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check app render models tests scripts benchmarks

setup: $(STAMP) native

# The primitives' C march, built into the user's cache (once per source); without a compiler the torch march runs.
native: $(STAMP)
ifeq ($(CC_FOUND),)
	@echo "no C compiler found (cc, gcc or clang): the primitives' march runs in torch; install build-essential for the C march"
else
	@echo "C compiler: $(CC_FOUND)"
	@CC=$(CC_FOUND) $(PY) -m models.avatars.primitives.native
endif

$(SYSTAMP): scripts/setup_system.sh
	bash scripts/setup_system.sh
	mkdir -p $(VENV) && touch $@

$(STAMP): pyproject.toml scripts/setup_python.sh $(SYSTAMP)
	bash scripts/setup_python.sh $(VENV)
	touch $@

clean-venv:
	rm -rf $(VENV)
