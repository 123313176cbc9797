#!/usr/bin/env bash
# All tests: the Rust workspace (unit, integration and end-to-end tests, doc examples), then the
# Python module built as a wheel, installed into a private virtual environment, and its pytest
# suite. Everything builds in the release profile, so the README's first command
# (`cargo run --release ...`) has already compiled most of what the tests link. The slower
# checks (whole-record diagnoses, the long property test, the practice sets) are in
# scripts/test-slow.sh.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test (workspace, release profile)"
if cargo nextest --version >/dev/null 2>&1; then
  # nextest runs the tests of every binary side by side (cargo test runs binaries one after
  # another, leaving a core idle behind each binary's longest test); it runs no doc examples.
  cargo nextest run --workspace --release --locked --no-fail-fast --status-level fail --final-status-level slow
  cargo test --workspace --release --locked --doc
else
  cargo test --workspace --release --locked
fi

echo "== Python wheel + pytest"
venv="${ITAIPU_VENV:-target/venv}"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet pytest pytest-xdist pandas matplotlib mypy dask distributed
# the data-family generator's own test (tests/python/test_families_generator.py)
"$venv/bin/python" -m pip install --quiet -r tools/families/requirements.txt
"$venv/bin/python" -m pip install --quiet --force-reinstall .
"$venv/bin/python" -m pytest tests/python -q -n 2
# (tests/python/test_pyapi.py also checks the type stub: mypy.stubtest against the installed
# module.)
