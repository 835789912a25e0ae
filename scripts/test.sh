#!/usr/bin/env bash
# The one test command (README, .ci/run): Rust checks and tests, then the wheel built once in
# release mode, installed into a fresh virtualenv, and the Python checks and tests against it.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
VENV="${LGI_TEST_VENV:-.venv-test}"

echo "== rust: fmt, clippy"
cargo fmt --all --check
cargo clippy --workspace --all-targets --release -- -D warnings

echo "== rust: tests (release)"
if cargo nextest --version >/dev/null 2>&1; then
  cargo nextest run --release --workspace --exclude lgi-python --no-fail-fast
else
  cargo test --release --workspace --exclude lgi-python
fi

echo "== browser: Debian's chromium and chromium-driver for the viewer's tests"
if ! { command -v chromium && command -v chromedriver; } >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" -ne 0 ] && command -v sudo >/dev/null 2>&1; then SUDO="sudo -n"; fi
  if ! { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
      $SUDO apt-get install -y -qq chromium chromium-driver; } >/dev/null 2>&1; then
    echo "could not install chromium: the browser tests will skip, saying so"
  fi
fi

echo "== python: fresh virtualenv $VENV"
rm -rf "$VENV"
python3 -m venv "$VENV"
# shellcheck disable=SC1091
. "$VENV/bin/activate"
python -m pip install --quiet --upgrade pip
python -m pip install --quiet "maturin>=1.9,<2"

echo "== python: build and install the wheel (release)"
rm -rf target/wheels
maturin build --release --quiet --out target/wheels
python -m pip install --quiet "$(ls target/wheels/lgi-*.whl)[test]"

echo "== python: ruff, mypy, stubs, pytest"
ruff check python tests scripts
ruff format --check python tests scripts
python -m mypy python/lgi
python -m mypy.stubtest lgi._lgi --allowlist scripts/stubtest-allowlist.txt
# Run from outside the checkout so tests import the installed wheel, not python/lgi.
(cd tests && python -m pytest -q -p no:cacheprovider .)

echo "== all checks passed in $(( $(date +%s) - start )) s"
