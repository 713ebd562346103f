# The README's two commands are `make run` and `make test`; both set everything up first.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= results

.PHONY: setup run test bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	@command -v $(PYTHON) >/dev/null || { echo "need $(PYTHON) (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[fast,test]'
	touch $@

run: setup
	$(BIN)/persival run --out $(OUT)

test: setup
	$(BIN)/pytest -n 2 -q

bench: setup
	$(BIN)/persival bench fe
	$(BIN)/persival bench sg

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
