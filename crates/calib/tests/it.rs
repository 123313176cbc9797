//! The integration tests of `itaipu-calib` that the README's test command runs, one binary:
//! each file beside this one is a module (a binary per file linked the whole workspace once
//! per file). The end-to-end diagnoses of whole records (tens of seconds each) are in
//! `slow.rs`; `no_panic` keeps its own binary because it installs a process-wide panic hook.

mod common;

mod bounded_swarm;
mod bounds;
mod comments;
mod diagnose;
mod field_channels;
mod fuzz_spec;
mod gradient;
mod input_smoothing;
mod mostar;
mod objective;
mod penalty;
mod playback_modes;
mod python_diagnose;
mod recovery;
mod sens_jacobian;
mod upside_down_bounds;
mod user_cause;
mod zero_particles;
