//! The integration tests of `itaipu-dynamics`, one binary: each file beside this one is a
//! module (a binary per file linked the whole crate once per file). `diagram_alloc` keeps its
//! own binary: it installs a counting global allocator.

mod event_support;
mod exciter_support;
mod playback_support;

mod andes_exciters;
mod andes_reference;
mod diagram_builtin;
mod diagram_errors;
mod diagram_primitives;
mod dyr;
mod event_csv;
mod event_declare;
mod event_memory;
mod event_onset;
mod event_toml;
mod event_window;
mod exciters;
mod extensions;
mod fuzz_readers;
mod integrator_convergence;
mod param_names;
mod plausibility;
mod playback_modes;
mod pmu_import;
mod sensitivities;
mod soft_knots;
mod st5b_reference;
mod steady_state;
mod unit_edit;
mod watched_playback;
