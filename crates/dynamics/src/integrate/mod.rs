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
//! first) with the state there. The one exception: a knot the system declares soft
//! ([`OdeSystem::soft_knot`]: the input is a cubic spline there, a low-passed record's), which
//! Dormand-Prince steps over, observing it on the step's dense output (fourth order: its error
//! is of the step's own order, within the tolerance); RK4 still lands on it.
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
//! **Event details.** Crossing times are located to 1e-12 s (never coarser than 1e-10 of the
//! step). The crossing is confirmed on the re-taken step: [`OdeSystem::handle_event`] is only
//! called with a state at which some event function is `<= 0`; if the re-taken step has not
//! crossed yet (interpolant and step differ slightly) it is kept as an ordinary step and the next
//! step finds the crossing. A crossing less than 1e-12 s after an event is ignored, and more than
//! 100 consecutive events each less than 1 ns apart stop the integration with
//! [`SolveError::EventLoop`] (chattering modes).
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

    /// Whether the right-hand side is smooth across interior knot `k` (the input interpolated
    /// by one polynomial piece on each side with continuous first and second derivatives): the
    /// adaptive integrator may then step over it and hand the observer the state there from the
    /// step's dense output ([`dopri5`]). `false` (the default) stops a step on every knot.
    fn soft_knot(&self, _k: usize) -> bool {
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
    /// Adaptive Dormand-Prince 5(4) that appends the end of every accepted step to a log, for a
    /// [`Method::Replay`] of the same run.
    Dopri5Logged(Dopri5Options, StepLog),
    /// The Dormand-Prince steps of an earlier logged run, retaken without error control
    /// ([`dopri5::replay`]): a smooth function of the parameters, for derivatives by differences.
    Replay(StepTimes),
}

/// Where a [`Method::Dopri5Logged`] run writes its step ends: shared, so that the caller keeps
/// a handle while the options travel down to the integrator; successive solves (the segments
/// of a set-point playback) append. Two logs are equal only when they are the same log.
#[derive(Debug, Clone, Default)]
pub struct StepLog(std::sync::Arc<std::sync::Mutex<Vec<f64>>>);

impl PartialEq for StepLog {
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

impl StepLog {
    /// The step ends logged so far, sorted (a replay's schedule).
    pub fn times(&self) -> StepTimes {
        let mut v = self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        v.sort_by(f64::total_cmp);
        StepTimes(v.into())
    }
    fn append(&self, ends: &[f64]) {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .extend_from_slice(ends);
    }
}

/// The sorted step ends of a logged run ([`StepLog::times`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StepTimes(pub std::sync::Arc<[f64]>);

impl StepTimes {
    pub fn len(&self) -> usize {
        self.0.len()
    }
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Method::Rk4 { h } => write!(f, "RK4, h = {} ms", h * 1e3),
            Method::Dopri5(o) | Method::Dopri5Logged(o, _) => {
                write!(f, "Dopri5, rtol {:e}, atol {:e}", o.rtol, o.atol)
            }
            Method::Replay(s) => write!(f, "Dopri5 replay of {} steps", s.len()),
        }
    }
}

/// An integrator name that is neither `dopri5` nor `rk4`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("must be 'dopri5' or 'rk4' (got '{0}')")]
pub struct UnknownMethod(pub String);

impl std::str::FromStr for Method {
    type Err = UnknownMethod;
    /// `dopri5` (the settings of [`crate::simulate::SimOptions::default`]) or `rk4` (1 ms
    /// steps), in any case.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "dopri5" => Ok(crate::simulate::SimOptions::default().method),
            "rk4" => Ok(Method::Rk4 { h: 0.001 }),
            _ => Err(UnknownMethod(s.to_string())),
        }
    }
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
    /// Step over the knots the system declares soft ([`OdeSystem::soft_knot`]: inside a
    /// smoothed input's spline), observing them on the steps' dense output, instead of ending a
    /// step on every knot. For searches, which need a candidate's ranking, not its last digit:
    /// the steps are then set by the dynamics, not by the sample rate. Off by default, and
    /// ignored by a logged run ([`Method::Dopri5Logged`]), whose replay lands on every knot:
    /// every derivative the project takes (sensitivities, replayed differences) is of the
    /// knot-landing map, where the jump at a located switch is exact to the step's order.
    pub soft_knots: bool,
}

impl Dopri5Options {
    /// The searches' tolerances (swarms and grid scans, which rank candidates and hand every
    /// result to a local method): rtol 1e-4, atol 1e-5, steps of at most 50 ms and a budget of
    /// 25 000 steps; the calibrator's `problem::search_integrator` gives the reasons. Landing
    /// on every sample (`soft_knots` off).
    pub fn search() -> Self {
        Self {
            rtol: 1e-4,
            atol: 1e-5,
            h_max: 0.05,
            max_steps: 25_000,
            ..Self::default()
        }
    }
}

impl Default for Dopri5Options {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-8,
            h_max: 0.1,
            h_init: 0.0,
            max_steps: 5_000_000,
            soft_knots: false,
        }
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
    #[error("more than 100 events less than 1 ns apart at t = {t:.9} s (modes chatter)")]
    EventLoop { t: f64 },
    /// RK4 cannot follow the system at this step: a mode of the state Jacobian at the start
    /// has `h·|λ|` beyond RK4's stability region ([`rk4::RK4_STABLE_HLAMBDA`]).
    #[error(
        "RK4 at h = {h:e} s cannot follow a mode of {rate:.1} 1/s (time constant {:.2e} s) at the start: take a shorter step or dopri5",
        1.0 / rate
    )]
    Stiff { h: f64, rate: f64 },
    /// The observer asked to stop at this knot ([`GoOn`]): not a failure of the integration.
    #[error("stopped by the observer at t = {t:.6} s")]
    Stopped { t: f64 },
}

/// What an observer returns: `()` (the run goes on to the last knot) or a `bool` (`false` stops
/// the run at that knot with [`SolveError::Stopped`]: a caller that has seen enough, say a
/// least-squares sum already above what it needs, does not pay for the rest).
pub trait GoOn {
    fn go_on(self) -> bool;
}

impl GoOn for () {
    #[inline(always)]
    fn go_on(self) -> bool {
        true
    }
}

impl GoOn for bool {
    #[inline(always)]
    fn go_on(self) -> bool {
        self
    }
}

/// Integrates `sys` from `knots[0]` to the last knot starting at `x` (overwritten with the final
/// state), calling `observer(k, t_k, x_k, sys)` at every knot `k` (the first call is at `k = 0`
/// after the initial [`OdeSystem::handle_event`]). An observer that returns `false` ([`GoOn`])
/// stops the run there: [`SolveError::Stopped`].
pub fn solve<S, O, G>(
    method: &Method,
    sys: &mut S,
    x: &mut [f64],
    knots: &[f64],
    observer: O,
) -> Result<Stats, SolveError>
where
    S: OdeSystem,
    O: FnMut(usize, f64, &[f64], &mut S) -> G,
    G: GoOn,
{
    match method {
        Method::Rk4 { h } => Rk4::new(*h)?.solve(sys, x, knots, observer),
        Method::Dopri5(opts) => Dopri5::new(opts.clone())?.solve(sys, x, knots, observer),
        Method::Dopri5Logged(opts, log) => {
            let mut ends = vec![];
            let res =
                Dopri5::new(opts.clone())?.solve_logged(sys, x, knots, observer, Some(&mut ends));
            log.append(&ends);
            res
        }
        Method::Replay(steps) => dopri5::replay(sys, x, knots, &steps.0, observer),
    }
}

// ------------------------------------------------------------------------------------------------
// Shared driver helpers (private to the integrators).

/// Event times are located to this absolute tolerance (s) ...
const EVENT_TOL_ABS: f64 = 1e-12;
/// ... but never coarser than this fraction of the step being searched.
const EVENT_TOL_REL: f64 = 1e-10;
/// A crossing closer than this (s) to the previous event is ignored (no re-trigger loops).
const EVENT_DEADBAND: f64 = 1e-12;
/// Consecutive events closer than this (s) to each other count as one instant.
const EVENT_INSTANT: f64 = 1e-9;
/// More events than this at one instant is reported as [`SolveError::EventLoop`].
const MAX_EVENTS_PER_INSTANT: usize = 100;

/// Validates the knots and the state length, calls the initial [`OdeSystem::handle_event`] at
/// `knots[0]` and checks that the resulting state is finite.
fn begin<S: OdeSystem>(sys: &mut S, x: &mut [f64], knots: &[f64]) -> Result<(), SolveError> {
    let Some(&t0) = knots.first() else {
        return Err(SolveError::BadKnots {
            index: 0,
            t: f64::NAN,
        });
    };
    if !t0.is_finite() {
        return Err(SolveError::BadKnots { index: 0, t: t0 });
    }
    for (i, w) in knots.windows(2).enumerate() {
        if !(w[1] > w[0] && w[1].is_finite()) {
            return Err(SolveError::BadKnots {
                index: i + 1,
                t: w[1],
            });
        }
    }
    if x.len() != sys.dim() {
        return Err(SolveError::BadSetting(format!(
            "state has {} entries but the system has {} states",
            x.len(),
            sys.dim()
        )));
    }
    sys.handle_event(t0, x);
    check_finite(t0, x)
}

/// `Err(NonFinite)` naming the first non-finite entry of `x`.
fn check_finite(t: f64, x: &[f64]) -> Result<(), SolveError> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(state) => Err(SolveError::NonFinite { t, state }),
        None => Ok(()),
    }
}

/// Sign tracking and location of event-function crossings, shared by both methods.
///
/// `g_start` holds the event functions at the start of the current step, `g_end` at the end of
/// the step just taken. A crossing is `g_start[i] > 0 && g_end[i] <= 0`.
struct Events {
    g_start: Vec<f64>,
    g_end: Vec<f64>,
    g_probe: Vec<f64>,
    x_probe: Vec<f64>,
    last_event: f64,
    burst_len: usize,
}

impl Events {
    fn new<S: OdeSystem>(sys: &S) -> Self {
        let m = sys.n_events();
        let n = if m > 0 { sys.dim() } else { 0 };
        Self {
            g_start: vec![0.0; m],
            g_end: vec![0.0; m],
            g_probe: vec![0.0; m],
            x_probe: vec![0.0; n],
            last_event: f64::NEG_INFINITY,
            burst_len: 0,
        }
    }

    /// Evaluates the event functions at the start of a step (after the start or an event).
    fn restart<S: OdeSystem>(&mut self, sys: &mut S, t: f64, x: &[f64]) {
        if !self.g_start.is_empty() {
            sys.events(t, x, &mut self.g_start);
        }
    }

    /// Evaluates the event functions at the end `(t1, x1)` of a step; `true` if one crossed.
    fn crossed<S: OdeSystem>(&mut self, sys: &mut S, t1: f64, x1: &[f64]) -> bool {
        if self.g_start.is_empty() {
            return false;
        }
        sys.events(t1, x1, &mut self.g_end);
        self.g_start
            .iter()
            .zip(&self.g_end)
            .any(|(&a, &b)| a > 0.0 && b <= 0.0)
    }

    /// The step end becomes the next step start.
    fn step_accepted(&mut self) {
        std::mem::swap(&mut self.g_start, &mut self.g_end);
    }

    /// Earliest crossing time in `(t0, t1]` (after [`Events::crossed`] returned `true`), or
    /// `None` if every crossing lies within [`EVENT_DEADBAND`] of the previous event.
    /// `interp(t, out)` writes the state at `t` (dense output or Hermite interpolation). The
    /// returned time is the end of the final bracket, where the interpolated `g_i <= 0`.
    fn locate<S, F>(&mut self, sys: &mut S, t0: f64, t1: f64, mut interp: F) -> Option<f64>
    where
        S: OdeSystem,
        F: FnMut(f64, &mut [f64]),
    {
        let tol = EVENT_TOL_ABS
            .min(EVENT_TOL_REL * (t1 - t0))
            .max(4.0 * f64::EPSILON * t1.abs());
        let Events {
            g_start,
            g_end,
            g_probe,
            x_probe,
            last_event,
            ..
        } = self;
        let mut g = |i: usize, t: f64| {
            interp(t, x_probe);
            sys.events(t, x_probe, g_probe);
            g_probe[i]
        };
        // Search only after the dead band; a crossing inside it is ignored.
        let lo = t0.max(*last_event + EVENT_DEADBAND);
        let mut earliest: Option<f64> = None;
        for (i, (&ga, &gb)) in g_start.iter().zip(g_end.iter()).enumerate() {
            if !(ga > 0.0 && gb <= 0.0) || lo >= t1 {
                continue;
            }
            let g_lo = if lo > t0 { g(i, lo) } else { ga };
            if g_lo > 0.0 {
                let te = illinois(lo, g_lo, t1, gb, tol, |t| g(i, t));
                earliest = Some(earliest.map_or(te, |e| e.min(te)));
            }
        }
        earliest
    }

    /// Records an event handled at `t`; fails when more than [`MAX_EVENTS_PER_INSTANT`]
    /// consecutive events are each within [`EVENT_INSTANT`] of the one before.
    fn record(&mut self, t: f64) -> Result<(), SolveError> {
        if t - self.last_event <= EVENT_INSTANT {
            self.burst_len += 1;
        } else {
            self.burst_len = 1;
        }
        self.last_event = t;
        if self.burst_len > MAX_EVENTS_PER_INSTANT {
            return Err(SolveError::EventLoop { t });
        }
        Ok(())
    }
}

/// Illinois (modified regula falsi) on a bracket with `ga = g(a) > 0`, `gb = g(b) <= 0`.
/// Returns the right end of the final bracket (so `g <= 0` there) once it is narrower than
/// `tol`, `g` hits zero exactly, no float lies strictly inside, or after 200 evaluations (only
/// reached at multiple roots; a triple root needs about 140).
fn illinois(
    mut a: f64,
    mut ga: f64,
    mut b: f64,
    mut gb: f64,
    tol: f64,
    mut g: impl FnMut(f64) -> f64,
) -> f64 {
    let mut kept = 0; // +1: `a` moved last time (b kept), -1: `b` moved last time
    for _ in 0..200 {
        if b - a <= tol {
            break;
        }
        let mut c = b - gb * (b - a) / (gb - ga);
        if !(c > a && c < b) {
            c = 0.5 * (a + b);
            if !(c > a && c < b) {
                break;
            }
        }
        let gc = g(c);
        if gc > 0.0 {
            a = c;
            ga = gc;
            if kept == 1 {
                gb *= 0.5;
            }
            kept = 1;
        } else {
            b = c;
            gb = gc;
            if gc == 0.0 {
                break;
            }
            if kept == -1 {
                ga *= 0.5;
            }
            kept = -1;
        }
    }
    b
}
