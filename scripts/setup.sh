#!/usr/bin/env bash
# Installs everything InkSlice needs on a Debian machine, idempotently:
# the Debian packages (AVR toolchain, simavr, LinuxCNC's G-code interpreter,
# chromium for browser tests, ...), then a venv in .venv: the Python dependencies at
# the versions and hashes of the lock files (requirements.lock, and
# requirements-test.lock for the tests; `make lock` refreshes them), then the
# package itself in editable mode without resolving anything. A second run with
# nothing missing does no network traffic.
#
#   scripts/setup.sh          what `make demo` needs
#   scripts/setup.sh --test   plus what `make test` needs
set -euo pipefail
cd "$(dirname "$0")/.."

want_test=0
[ "${1:-}" = "--test" ] && want_test=1

# Needed to run the appliance on the simulated bench.
APT_RUN=(python3 python3-venv python3-dev build-essential pkg-config
         gcc-avr avr-libc binutils-avr simavr libsimavr-dev libelf-dev)
# Needed by the test suite and the benches on top of that.
# clang-format checks the firmware's layout (`make lint`, tests/test_lint.py).
APT_TEST=(libcmocka-dev clang libclang-rt-14-dev clang-format chromium chromium-driver
          systemd linuxcnc-uspace)
# npm (for axe-core, below) only where no node toolchain is installed already
[ "$want_test" = 1 ] && ! command -v npm >/dev/null 2>&1 && APT_TEST+=(npm)

pkgs=("${APT_RUN[@]}")
[ "$want_test" = 1 ] && pkgs+=("${APT_TEST[@]}")

missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  # linuxcnc-uspace pulls a desktop's worth of recommends; we only want rs274.
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PY" -m venv .venv
fi
# The stamp records what was installed from which files: a --test install also serves `make demo`.
lock=requirements.lock; mode=run
[ "$want_test" = 1 ] && { lock=requirements-test.lock; mode=test; }
stamp=.venv/.inkslice-installed
sig=$(cat pyproject.toml requirements.lock requirements-test.lock | sha256sum | cut -d' ' -f1)
have=$(cat "$stamp" 2>/dev/null || true)
if [ "$have" != "$sig test" ] && [ "$have" != "$sig $mode" ]; then
  echo "setup: installing Python packages into .venv (pinned by $lock)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q --require-hashes -r "$lock"
  .venv/bin/python -m pip install -q --no-deps -e .
  echo "$sig $mode" > "$stamp"
fi

# axe-core, the accessibility checker the browser tests run inside chromium, at the version and
# integrity hash of tests/a11y/package-lock.json (npm ci checks it); skipped when already there.
if [ "$want_test" = 1 ]; then
  want_axe=$(sed -n 's/.*"axe-core": "\(.*\)".*/\1/p' tests/a11y/package.json)
  have_axe=$(sed -n 's/^  "version": "\(.*\)".*/\1/p' tests/a11y/node_modules/axe-core/package.json 2>/dev/null || true)
  if [ "$have_axe" != "$want_axe" ]; then
    echo "setup: installing axe-core $want_axe into tests/a11y (pinned by its package-lock.json)"
    (cd tests/a11y && npm ci --no-audit --no-fund --silent)
  fi
fi
