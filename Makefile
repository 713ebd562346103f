# The README's two commands are `make run` and `make test`; both set everything up first.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
OUT    ?= results
WEB    := persival/deploy/web
WEB_SRC := $(WEB)/package.json $(WEB)/package-lock.json $(WEB)/build.mjs $(WEB)/index.html $(wildcard $(WEB)/src/*) $(wildcard $(WEB)/src/*/*)

.PHONY: setup lock web chromium run lint test test-fast bench clean

setup: $(VENV)/.installed web

# The web viewer (persival serve serves it): npm ci installs package-lock.json's exact versions,
# esbuild bundles it into $(WEB)/dist; each step reruns only when its inputs are newer.
web: $(WEB)/dist/index.html

$(WEB)/node_modules/.package-lock.json: $(WEB)/package-lock.json
	@command -v npm >/dev/null || { echo "need node >= 18 and npm to build the web viewer"; exit 1; }
	cd $(WEB) && npm ci --no-audit --no-fund
	touch $@

$(WEB)/dist/index.html: $(WEB_SRC) $(WEB)/node_modules/.package-lock.json
	cd $(WEB) && npm run build

# Headless Chromium for the viewer tests: installed from Debian when missing (CI runs as root on
# a fresh machine); elsewhere the viewer tests skip with a message.
chromium:
	@test -x /usr/bin/chromium || { if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver; \
	  else echo "warning: no /usr/bin/chromium (apt-get install chromium): the viewer tests will skip"; fi; }

# requirements.lock pins every package of '.[fast,test]' exactly (torch: the CPU build), so each
# setup installs the same versions; the project itself goes in without its ranges (--no-deps),
# and pip check fails the setup when the lock no longer satisfies pyproject.toml (run make lock).
$(VENV)/.installed: pyproject.toml requirements.lock
	@command -v $(PYTHON) >/dev/null || { echo "need $(PYTHON) (set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	# --no-compile: Python byte-compiles each module on its first import instead of all of them
	# now (torch's thousands): 58 s against 88 s for this step
	$(BIN)/pip install --quiet --no-compile -r requirements.lock
	$(BIN)/pip install --quiet --no-compile --no-deps -e .
	$(BIN)/pip check
	touch $@

# Regenerate requirements.lock after a change to the dependencies in pyproject.toml: `make lock`
# keeps the pins that still fit and resolves only what changed; `make lock UPGRADE=1` takes the
# newest releases of everything. pip-compile (pip-tools, in a throwaway venv) resolves
# '.[fast,test]' with pip, which takes torch 2.13.0's CPU build from this machine's wheel folder
# (uv would resolve a CUDA build); the grep fails the target when the lock names a CUDA package.
PIP_TOOLS := pip-tools==7.7.0
lock:
	tmp=$$(mktemp -d) && trap 'rm -rf "$$tmp"' EXIT && $(PYTHON) -m venv "$$tmp" \
	  && "$$tmp/bin/pip" install --quiet '$(PIP_TOOLS)' \
	  && "$$tmp/bin/pip-compile" --quiet $(if $(UPGRADE),--upgrade) --extra=fast --extra=test --allow-unsafe \
	     --strip-extras --no-emit-find-links --no-emit-index-url --output-file=requirements.lock pyproject.toml
	@! grep -inE '^(nvidia|triton)' requirements.lock || { echo "requirements.lock pulls a CUDA torch"; exit 1; }

run: setup
	$(BIN)/persival run --out $(OUT)

# ruff: the rules and their reasons are in pyproject.toml ([tool.ruff])
lint: setup
	$(BIN)/ruff check persival tests

test: setup chromium lint
	$(BIN)/pytest -n 2 --dist loadfile -q

# The quick loop while editing: everything not marked slow (FE solves of the arm, trained
# networks, the browser), under 2 minutes on 2 cores.
test-fast: setup lint
	$(BIN)/pytest -n 2 --dist loadfile -q -m "not slow"

bench: setup
	$(BIN)/persival bench fe
	$(BIN)/persival bench sg

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
