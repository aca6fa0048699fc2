# The two Quick start commands are `make demo` and `make test`; each installs
# what it needs first (scripts/setup.sh is idempotent).
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: demo test setup setup-test bench clean install lock docs firmware-test lint

# HOST=0.0.0.0 lets a phone on the same network reach the demo's web UI
HOST ?= 127.0.0.1
demo: setup
	$(VENV)/bin/inkslice demo --serve --host $(HOST)

test: setup-test
	$(PY) -m pytest -q

setup:
	@scripts/setup.sh

setup-test:
	@scripts/setup.sh --test

# The firmware's cmocka host tests (ASan/UBSan) and a short libFuzzer run of its line parser
# (FUZZ_SECONDS=20); needs cc, clang and libcmocka-dev, no Python
firmware-test:
	$(MAKE) -C appliance/firmware/stepper test

# ruff (lint and layout) on the Python tree, mypy on the typed rooms (pyproject.toml's
# [tool.mypy] files), clang-format on the firmware's C; CI runs the same through tests/test_lint.py
lint: setup-test
	$(VENV)/bin/ruff check
	$(VENV)/bin/ruff format --check
	$(VENV)/bin/mypy
	$(MAKE) -s -C appliance/firmware/stepper format-check

bench: setup-test
	for b in benches/*.py; do $(PY) $$b --quick || exit 1; done

# The pinned Python packages (requirements.lock, requirements-test.lock): newest versions
# in pyproject.toml's ranges, with their hashes; run `make test` before committing them
lock:
	scripts/lock.sh

# docs/settings.md from the settings' definitions (tests/test_docs.py checks it is current)
docs: setup
	$(PY) scripts/gen_settings_doc.py

# On the bench box (Raspberry Pi OS): services, udev rules, user; see systemd/install.sh
install:
	sudo systemd/install.sh

clean:
	rm -rf demo-out benches/out tests/artifacts
