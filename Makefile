# The single entry point. `make demo` and `make test` set up everything they need on a fresh machine.
.PHONY: setup demo test test-fast lint typecheck fix bench clean compose

PY := .venv/bin/python
RUFF := .venv/bin/ruff
MYPY := .venv/bin/mypy
LINT_HINT := run 'make fix' (or: $(RUFF) check --fix . && $(RUFF) format .), then fix by hand what ruff still reports

setup:
	@bash scripts/setup.sh

demo: setup
	@$(PY) -m demo $(DEMO_ARGS)

# lint (complexity <= 12 and at most 8 arguments included, [tool.ruff.lint] in pyproject.toml), format and types
# are checked first: a finding fails the run before the (slow) tests start; the 30 slowest tests are listed at the end
# (where CI time goes). TEST_WORKERS=N runs the tests in N processes (pytest-xdist, a whole module per worker:
# --dist loadfile); the default, 0, runs them in one: with two workers on 2 cores a loaded machine failed 11 tests
# (docs/foundation.md, "CI time")
TEST_WORKERS ?= 0
XDIST_ARGS := $(if $(filter-out 0,$(TEST_WORKERS)),-n $(TEST_WORKERS) --dist loadfile)
test:
	@bash scripts/setup.sh --test
	@$(MAKE) --no-print-directory _lint
	@$(PY) -m pytest -q --durations=30 $(XDIST_ARGS) $(PYTEST_ARGS)

test-fast:
	@bash scripts/setup.sh --test
	@$(MAKE) --no-print-directory _lint
	@$(PY) -m pytest -q -m "not integration and not docker" $(PYTEST_ARGS)

lint:
	@bash scripts/setup.sh --test
	@$(MAKE) --no-print-directory _lint

# mypy over every package, the services' shells, hri/, testkit/, demo/, benchmarks/ and tests/ included (the scope is
# [tool.mypy] in pyproject.toml)
typecheck:
	@bash scripts/setup.sh --test
	@$(MAKE) --no-print-directory _typecheck

_lint:
	@$(RUFF) check . || { echo "make: ruff check found the problems above: $(LINT_HINT)" >&2; exit 1; }
	@$(RUFF) format --check . || { echo "make: the files above are not formatted: $(LINT_HINT)" >&2; exit 1; }
	@$(MAKE) --no-print-directory _typecheck

_typecheck:
	@$(MYPY) || { echo "make: mypy found the type errors above: fix the annotations or the code (docs/foundation.md, 'Type check')" >&2; exit 1; }

fix:
	@bash scripts/setup.sh --test
	@$(RUFF) check --fix .
	@$(RUFF) format .

# docker-compose.yml is written from common/stack.py; tests/test_stack.py fails when it is stale
compose:
	@$(PY) -m hri.compose --write

BENCHMARKS := transport vision gesture pose_pacing stagger faces speech fusion fusion_eval record_replay view pointing_3d distributed ros2 stack

bench: setup
	@for b in $(BENCHMARKS); do echo "== benchmarks/$$b.py"; $(PY) benchmarks/$$b.py || exit 1; done

clean:
	rm -rf .venv .pytest_cache .mypy_cache
