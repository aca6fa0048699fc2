#!/usr/bin/env bash
# Refreshes the lock files (`make lock`): every Python package InkSlice installs, pinned to
# one version with the sha256 of each of its files on PyPI (all platforms: the x86_64
# machines that run CI and the aarch64 Raspberry Pi the box runs on).
#
#   requirements.lock        what the box runs (systemd/install.sh)
#   requirements-test.lock   plus the test suite's tools (scripts/setup.sh, CI)
#
# Both are resolved from pyproject.toml's ranges, newest first, the test lock first and the
# run lock inside it, so the two agree on every package they share. Run `make test` after a
# refresh and commit the lock files with the result: they are the versions the tests ran.
#   scripts/lock.sh              newest versions in pyproject.toml's ranges
#   scripts/lock.sh --keep       keep the pinned versions, only add what pyproject.toml now asks for
set -euo pipefail
cd "$(dirname "$0")/.."
upgrade=--upgrade
[ "${1:-}" = "--keep" ] && upgrade=""

# Hashes come from PyPI alone: a local mirror or wheel folder configured on this machine
# would add hashes of files the box can never download.
export PIP_CONFIG_FILE=/dev/null
unset PIP_FIND_LINKS PIP_EXTRA_INDEX_URL PIP_INDEX_URL PIP_CONSTRAINT PIP_NO_INDEX || true

tools=$(mktemp -d)
trap 'rm -rf "$tools"' EXIT
python3 -m venv "$tools/venv"
"$tools/venv/bin/python" -m pip install -q "pip-tools==7.6.2"

compile() {   # OUTPUT [pip-compile options...]
  local out=$1; shift
  CUSTOM_COMPILE_COMMAND="make lock" "$tools/venv/bin/pip-compile" -q $upgrade --generate-hashes --allow-unsafe --strip-extras \
      --index-url https://pypi.org/simple --no-emit-index-url \
      --output-file "$out" "$@" pyproject.toml
}
compile requirements-test.lock --extra test
compile requirements.lock -c requirements-test.lock
echo "lock: requirements.lock and requirements-test.lock written; now run make test"
