# The two Quick start commands are `make demo` and `make test`; each installs
# what it needs first (scripts/setup.sh is idempotent).
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo test setup setup-test bench clean

demo: setup
	$(VENV)/bin/inkslice demo

test: setup-test
	$(PY) -m pytest -q

setup:
	@scripts/setup.sh

setup-test:
	@scripts/setup.sh --test

bench: setup-test
	for b in benches/*.py; do $(PY) $$b --quick || exit 1; done

clean:
	rm -rf demo-out benches/out tests/artifacts
