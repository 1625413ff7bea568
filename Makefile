# The single entry point. `make demo` and `make test` set up everything they need on a fresh machine.
.PHONY: setup demo test test-fast bench clean

PY := .venv/bin/python

setup:
	@bash scripts/setup.sh

demo: setup
	@$(PY) -m demo $(DEMO_ARGS)

test:
	@bash scripts/setup.sh --test
	@$(PY) -m pytest -q $(PYTEST_ARGS)

test-fast:
	@bash scripts/setup.sh --test
	@$(PY) -m pytest -q -m "not integration and not docker" $(PYTEST_ARGS)

BENCHMARKS := transport vision gesture speech fusion fusion_eval record_replay view

bench: setup
	@for b in $(BENCHMARKS); do echo "== benchmarks/$$b.py"; $(PY) benchmarks/$$b.py || exit 1; done

clean:
	rm -rf .venv .pytest_cache
