//! # itaipu-dynamics
//!
//! Playback simulation of a generating unit (synchronous machine, exciter, stabiliser,
//! turbine-governor) driven by a measured terminal-voltage phasor, as used for PMU-based model
//! validation and calibration (NERC MOD-026/027 style).
//!
//! * [`models`]: the model library, equations in each file's documentation, following
//!   `shared/reference/models.md` (PSS/E and OpenIPSL conventions, per unit on the machine base).
//! * [`unit`]: blocks wired by named signals into one explicit ODE; the playback source.
//! * [`integrate`]: fixed-step RK4 and adaptive Dormand-Prince 5(4) with dense output and
//!   event location for limiter switches.
//! * [`event`]: measured events (TOML + CSV), validation, pre-event operating point.
//! * [`unit_file`]: unit model files (TOML).
//! * [`diagram`]: user-defined control models (block diagrams declared in TOML).
//! * [`simulate`]: the playback simulation and its traces.
//! * [`mode`]: playback modes that need no voltage angle (exciter alone, machine from E_fd,
//!   closed loop against a grid equivalent) and set-point steps.

// Parameter and state guards are written `!(x > 0.0)` on purpose: that form also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod block;
pub mod diagram;
pub mod dyr;
pub mod event;
pub mod filter;
pub mod integrate;
pub mod mode;
pub mod models;
pub mod params;
pub mod plausibility;
pub mod pmu_import;
pub mod registry;
pub mod rng;
pub mod sens;
pub mod simulate;
pub mod synthetic;
pub mod unit;
pub mod unit_file;

pub use block::{Block, InitPoint, ModelError};
pub use event::{Event, EventError};
pub use integrate::{Dopri5Options, Method};
pub use simulate::{simulate, SimError, SimOptions, Traces};
pub use unit::{Unit, UnitError};
pub use unit_file::{read_unit, UnitFileError};
