#!/usr/bin/env bash
# The slower checks, which CI runs after scripts/test.sh (about 45 minutes on 2 cores):
# 1. the end-to-end fits and diagnoses of whole records (crates/calib/tests/slow.rs);
# 2. the property test of random units, specs and budgets with 2,000 cases
#    (crates/calib/tests/no_panic.rs; the test command runs 64);
# 3. the practice sets (data/practice: 66 records made by an independent implementation, one
#    calibration spec for all, the answer keys read only to score), fitted and diagnosed as a
#    user does, and the scores checked against the project's bars (`--check`).
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== slow integration tests"
cargo test --release --locked -p itaipu-calib --features slow-tests --test slow

echo "== property test, 2,000 cases"
ITAIPU_PROPTEST_CASES=2000 cargo test --release --locked -p itaipu-calib --test no_panic

echo "== practice sets"
repo="$PWD"
out="${ITAIPU_PRACTICE_OUT:-target/practice-run}"
mkdir -p "$out"
# The runner writes out/ in its working folder.
(cd "$out" && cargo run --release --locked --manifest-path "$repo/Cargo.toml" -p itaipu-calib \
  --example practice -- "$repo/data/practice" --check)
