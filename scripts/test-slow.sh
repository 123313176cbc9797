#!/usr/bin/env bash
# The slower checks CI runs after scripts/test.sh (about an hour on 2 cores; each section prints
# its wall time):
# 1. the property test of random units, specs and budgets with 2,000 cases
#    (crates/calib/tests/no_panic.rs; the test command runs 64);
# 2. the practice sets (data/practice: 66 records made by an independent implementation, one
#    calibration spec for all, the answer keys read only to score), fitted and diagnosed as a
#    user does, and the scores checked against the project's bars (`--check`).
# scripts/test-extended.sh runs the end-to-end diagnoses of synthetic records and every command
# of the documentation end to end (about 25 minutes more; not in CI's 90-minute budget).
set -euo pipefail
cd "$(dirname "$0")/.."

section() { echo "== $1 (after ${SECONDS} s)"; }

section "property test, 2,000 cases"
ITAIPU_PROPTEST_CASES=2000 cargo test --release --locked -p itaipu-calib --test no_panic

section "practice sets"
repo="$PWD"
out="${ITAIPU_PRACTICE_OUT:-target/practice-run}"
mkdir -p "$out"
# The runner writes out/ in its working folder.
(cd "$out" && cargo run --release --locked --manifest-path "$repo/Cargo.toml" -p itaipu-calib \
  --example practice -- "$repo/data/practice" --check)
section "done"
