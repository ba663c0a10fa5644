# The two set-up commands: `make demo` (main job) and `make test` (whole test suite).
# Both create .venv and install everything: the survey server (the base install), the offline side (the `search`
# extra), the report's figures, highway driving and the test tools. PyTorch is pinned first so that a machine with
# a local CPU wheel (or a GPU machine, which gets the regular build) satisfies the `search` extra's `torch`
# requirement without pulling a second build. The editable install leaves out setuptools' notice that folders named
# as a package could shadow it: here the checkout is the package.
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
BIN = $(VENV)/bin
AXE = .cache/axe/node_modules/axe-core/axe.min.js
DEMO_BUNDLE ?= bundles/demo

.PHONY: demo demo-password test check lint lint-baseline install browser postgres r

install: $(VENV)/.installed

# What only the browser tests need: Debian's chromium (Playwright's own browser downloads are never used) and
# axe-core for the accessibility checks.
browser: $(AXE)
	@command -v chromium >/dev/null || (apt-get update && apt-get install -y chromium)

# What the PostgreSQL variants of the database tests need: Debian's postgresql (its initdb, pg_ctl and server; the
# tests start a throwaway cluster of their own on a loopback port, and stop it at the end).
postgres:
	@ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || command -v initdb >/dev/null || \
		(apt-get update && apt-get install -y postgresql)

# What the test of `foil export`'s glmer.R needs (and benchmarks/bench_clubsandwich.py): Debian's R with lme4 and
# clubSandwich. The server never needs R.
r:
	@Rscript -e 'library(lme4); library(clubSandwich)' >/dev/null 2>&1 || \
		(apt-get update && apt-get install -y --no-install-recommends r-base-core r-cran-lme4 r-cran-clubsandwich)

$(VENV)/.installed: pyproject.toml Makefile
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet "$(TORCH_SPEC)"
	PYTHONWARNINGS="ignore:Editable installation" $(BIN)/python -m pip install --quiet -e ".[search,figures,highway,dev]"
	touch $@

$(AXE):
	npm install --silent --no-audit --no-fund --prefix .cache/axe axe-core@4

# The demo: build the demo study's bundle from the shipped agents (small search budgets; searches and clips
# already built are reused), then serve it at http://127.0.0.1:8000/, with the admin pages at /admin. It prints what
# a researcher needs, not its command lines nor a line per request, so the address and password stay on screen.
demo: install
	@echo "Building the demo study. Its warnings are expected: its small searches find clips that show the worse"
	@echo "robot as better, which a study keeps to see how people read them (docs/clips.md); the gallery says which."
	@$(BIN)/foil bundle studies/demo.toml --out $(DEMO_BUNDLE) --jobs 2
	@$(MAKE) -s demo-password
	@FOIL_ADMIN_PASSWORD="$${FOIL_ADMIN_PASSWORD:-$$(cat $(DEMO_BUNDLE).admin-password)}" FOIL_ACCESS_LOG=false \
		$(BIN)/foil serve --bundle $(DEMO_BUNDLE) --db sqlite:///$(DEMO_BUNDLE).sqlite3

# The demo's admin password: FOIL_ADMIN_PASSWORD when set; otherwise one generated on the first `make demo`, kept
# in $(DEMO_BUNDLE).admin-password (readable by its owner only) and printed when the demo starts.
demo-password:
	@if [ -n "$$FOIL_ADMIN_PASSWORD" ]; then \
		echo "Admin pages: http://127.0.0.1:8000/admin with the password in FOIL_ADMIN_PASSWORD"; \
	else \
		mkdir -p "$$(dirname $(DEMO_BUNDLE))"; \
		[ -s $(DEMO_BUNDLE).admin-password ] || (umask 077; \
			python3 -c "import secrets; print(secrets.token_urlsafe(12))" > $(DEMO_BUNDLE).admin-password); \
		echo "Admin pages: http://127.0.0.1:8000/admin, password: $$(cat $(DEMO_BUNDLE).admin-password)"; \
		echo "(kept in $(DEMO_BUNDLE).admin-password; set FOIL_ADMIN_PASSWORD to choose your own)"; \
	fi

# Two tests at a time (pytest-xdist): each worker has its own fixtures, throwaway PostgreSQL server and browser.
test: lint install browser postgres r
	$(BIN)/python -m pytest -q -n 2

# The fast loop while working: everything but the slow and the browser tests (they run in `make test`).
check: lint install postgres
	$(BIN)/python -m pytest -q -n 2 -m "not slow and not browser"

# Lint and types (pyproject.toml configures all three). mypy is strict on app/, search/bundle/, search/core/,
# search/crowd/sim/ and search/solvers/; the rest of the tree may only lose the errors listed in mypy-baseline.txt:
# `mypy-baseline filter` fails on a new error and on a listed one that is gone (then `make lint-baseline` drops it),
# and the grep keeps the strict packages out of the baseline.
lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy | $(BIN)/mypy-baseline filter --no-colors
	@! grep -E '^(app|search/bundle|search/core|search/crowd/sim|search/solvers)/' mypy-baseline.txt || \
		(echo "mypy-baseline.txt lists errors in app/, search/bundle/, search/core/, search/crowd/sim/ or" \
		"search/solvers/, which must pass mypy strictly"; exit 1)

# Rewrite mypy-baseline.txt from the current errors (after fixing some, or to accept the current state).
lint-baseline: install
	$(BIN)/mypy | $(BIN)/mypy-baseline sync
