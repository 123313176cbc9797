//! The slower tier of `itaipu-calib`'s integration tests (`bash scripts/test-slow.sh`, which CI
//! runs after the test command): end-to-end fits and diagnoses of whole records, tens of
//! seconds each. Built only with the `slow-tests` feature, so that `cargo test` leaves them
//! out.

mod common;

mod diagnose_modes;
mod diagnose_named;
mod practice;
