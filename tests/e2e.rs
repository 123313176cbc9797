//! The end-to-end tests (the command line, the contract between the front ends), one binary:
//! each file beside this one is a module (a binary per file linked the whole workspace once per
//! file). `support/` is this package's library of helpers.

mod cli_diagnose;
mod cli_diagram;
mod cli_dyr;
mod cli_ecosys;
mod cli_fit;
mod cli_mostar;
mod cli_reliability;
mod cli_report;
mod cli_simulate;
mod cli_synth;
mod cli_user_cause;
mod contract;
