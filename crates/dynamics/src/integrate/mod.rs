//! Time integrators for explicit ODEs `dx/dt = f(t, x)` with discrete modes.
//!
//! Two methods share one driver ([`solve`]):
//!
//! * [`Method::Rk4`]: classical fourth-order Runge-Kutta at a fixed step `h`. Each interval
//!   between two knots is split into `ceil(Δ/h)` equal sub-steps, so steps land exactly on the
//!   knots (the playback sample instants).
//! * [`Method::Dopri5`]: the Dormand-Prince 5(4) embedded pair with FSAL, a PI step-size
//!   controller (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4 and the `dopri5` code) and the
//!   fourth-order continuous extension for dense output.
//!
//! **Knots.** The driver integrates from `knots[0]` to `knots[last]` and stops exactly at every
//! knot: no step straddles a knot. Playback inputs are interpolated linearly between samples, so
//! the right-hand side is smooth inside an interval and only continuous at the knots; stopping
//! there keeps the error estimate honest. The observer is called at every knot (including the
//! first) with the state there.
//!
//! **Discrete modes (limiters).** A system may expose event functions `g_i(t, x)`
//! ([`OdeSystem::n_events`], [`OdeSystem::events`]). While a step is taken the system's modes
//! are frozen, so the right-hand side is smooth. After each accepted step the driver compares the
//! sign of every `g_i` at both ends; when one goes from `> 0` to `<= 0` it locates the earliest
//! crossing (dense output for Dopri5, cubic Hermite for RK4; Illinois/regula-falsi to
//! `event_tol`), re-takes the step to the crossing, and calls [`OdeSystem::handle_event`], which
//! may switch modes and project the state (e.g. pin a non-windup state at its limit). Integration
//! then resumes from the event time. Convention: an event function is **positive while the
//! current mode remains valid**.
//!
//! All work buffers are allocated once per [`solve`] call; the step loop does not allocate.

pub mod dopri5;
pub mod rk4;

pub use dopri5::Dopri5;
pub use rk4::Rk4;

/// An explicit ODE system with optional discrete modes.
pub trait OdeSystem {
    /// Number of states.
    fn dim(&self) -> usize;

    /// Evaluates `dx = f(t, x)` with the current modes.
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]);

    /// Number of event (guard) functions; 0 for a purely continuous system.
    fn n_events(&self) -> usize {
        0
    }

    /// Evaluates the event functions at `(t, x)` with the current modes. Each is positive while
    /// the current mode stays valid; a crossing to `<= 0` asks for [`OdeSystem::handle_event`].
    fn events(&mut self, _t: f64, _x: &[f64], _g: &mut [f64]) {}

    /// Called at a located event and once before the first step: re-evaluates modes from the
    /// state, may project `x` (e.g. onto a limit). Returns `true` if a mode or `x` changed.
    fn handle_event(&mut self, _t: f64, _x: &mut [f64]) -> bool {
        false
    }
}

/// Integration method and its settings.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// Fixed-step classical RK4 with the largest step `h` [s] (steps are shortened to land on knots).
    Rk4 { h: f64 },
    /// Adaptive Dormand-Prince 5(4).
    Dopri5(Dopri5Options),
}

/// Settings for [`Method::Dopri5`].
#[derive(Debug, Clone, PartialEq)]
pub struct Dopri5Options {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Largest step [s].
    pub h_max: f64,
    /// First trial step [s]; 0 picks one automatically (Hairer's `hinit`).
    pub h_init: f64,
    /// Give up after this many steps (accepted + rejected).
    pub max_steps: usize,
}

impl Default for Dopri5Options {
    fn default() -> Self {
        Self { rtol: 1e-6, atol: 1e-8, h_max: 0.1, h_init: 0.0, max_steps: 5_000_000 }
    }
}

/// Counters from one integration.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    pub steps_accepted: usize,
    pub steps_rejected: usize,
    pub rhs_evals: usize,
    pub events: usize,
}

/// Why an integration stopped early.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("knots must be strictly increasing (knot {index} at t = {t} s)")]
    BadKnots { index: usize, t: f64 },
    #[error("state became non-finite at t = {t:.6} s (state {state})")]
    NonFinite { t: f64, state: usize },
    #[error("step size underflow at t = {t:.6} s (h = {h:e} s)")]
    StepUnderflow { t: f64, h: f64 },
    #[error("more than {max_steps} steps before t = {t:.6} s")]
    TooManySteps { t: f64, max_steps: usize },
    #[error("invalid integrator setting: {0}")]
    BadSetting(String),
}

/// Integrates `sys` from `knots[0]` to the last knot starting at `x` (overwritten with the final
/// state), calling `observer(k, t_k, x_k, sys)` at every knot `k` (the first call is at `k = 0`
/// after the initial [`OdeSystem::handle_event`]).
pub fn solve<S, O>(
    method: &Method,
    sys: &mut S,
    x: &mut [f64],
    knots: &[f64],
    observer: O,
) -> Result<Stats, SolveError>
where
    S: OdeSystem,
    O: FnMut(usize, f64, &[f64], &mut S),
{
    match method {
        Method::Rk4 { h } => Rk4::new(*h)?.solve(sys, x, knots, observer),
        Method::Dopri5(opts) => Dopri5::new(opts.clone())?.solve(sys, x, knots, observer),
    }
}
