#!/usr/bin/env bash
# Checks beyond CI's slow tier (about 25 minutes on 2 cores), run before a release:
# 1. the end-to-end fits and diagnoses of synthetic records, cause by cause and mode by mode
#    (crates/calib/tests/slow.rs);
# 2. the documentation's examples with every command run end to end (crates/cli/tests/docs.rs,
#    tests/python/test_docs.py; the test command runs the quick ones).
set -euo pipefail
cd "$(dirname "$0")/.."

section() { echo "== $1 (after ${SECONDS} s)"; }

section "slow integration tests"
cargo test --release --locked -p itaipu-calib --features slow-tests --test slow

section "the documentation's examples, every command run end to end"
cargo test --release --locked -p itaipu-calib-cli --features slow-tests --test it docs
ITAIPU_SLOW_TESTS=1 "${ITAIPU_VENV:-target/venv}/bin/python" -m pytest tests/python/test_docs.py -q
section "done"
