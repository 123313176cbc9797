#!/usr/bin/env bash
# All tests: the Rust workspace (unit, integration and end-to-end tests), then the Python
# module built as a wheel, installed into a private virtual environment, and its pytest suite.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo test (workspace)"
cargo test --workspace --locked

echo "== Python wheel + pytest"
venv="${ITAIPU_VENV:-target/venv}"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet pytest pandas matplotlib mypy dask distributed
# the data-family generator's own test (tests/python/test_families_generator.py)
"$venv/bin/python" -m pip install --quiet -r tools/families/requirements.txt
"$venv/bin/python" -m pip install --quiet --force-reinstall .
"$venv/bin/python" -m pytest tests/python -q
# (tests/python/test_pyapi.py also checks the type stub: mypy.stubtest against the installed
# module.)
