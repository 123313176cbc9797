//! A least-squares problem: a unit, its free parameters with bounds, and measured events.
//!
//! The objective (paper 000 eq. 3, RaPId's `J`) is
//!
//! ```text
//! J(x) = Σ_events Σ_{k in window} w_p (P_sim,k(x) − P_meas,k)² + w_q (Q_sim,k(x) − Q_meas,k)²
//! ```
//!
//! with P and Q in pu on each event's system base. Each event is simulated from its own
//! pre-event operating point. A candidate whose unit cannot initialise or whose simulation
//! fails gets a finite penalty; it is counted and the first messages are kept for the report.
//!
//! **Coordinates.** Optimisers never see physical values. A free parameter with bounds
//! `[lo, hi]` maps to `u ∈ [0, 1]` linearly, or logarithmically when `0 < lo` and `hi/lo >= 10`
//! (time constants and gains spanning decades), so the swarm searches decades evenly. L-BFGS,
//! which has no bounds, works on `z ∈ ℝ` with `u = 1/(1 + e^{−z})`.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use itaipu_dynamics::event::{Channel, Event, Window, MIN_SAMPLES};
use itaipu_dynamics::integrate::{Dopri5Options, Method, StepLog};
use itaipu_dynamics::mode::{simulate_mode, simulate_mode_watched, ModeOutputs};
use itaipu_dynamics::simulate::{simulate_pq, simulate_pq_watched, PreparedEvent, SimOptions};
use itaipu_dynamics::unit::{ParamRef, Unit};
use rayon::prelude::*;

use crate::spec::{Compare, Objective, Weights};

/// A free parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeParam {
    /// Canonical `block.name`.
    pub path: String,
    pub r: ParamRef,
    pub lo: f64,
    pub hi: f64,
    /// Logarithmic scaling of the unit coordinate.
    pub log: bool,
    /// Value at the start of the stage.
    pub start: f64,
    /// Unit of measure, for reports.
    pub unit: &'static str,
    /// What is known of the value before the data: see [`Prior`].
    pub prior: Option<Prior>,
}

/// A log-normal prior on a positive parameter: the value is believed to lie near `center` (a
/// datasheet or commissioning value) within a relative spread `spread` (standard deviation of
/// `ln(x/center)`). It adds the residual `σ·ln(x/center)/spread` to the problem (σ² =
/// [`Problem::prior_weight`], the variance of one measured residual), so the objective is
/// `σ²` times the negative log-posterior: a fit that moves a right value far from its datasheet
/// to mimic a missing effect pays for it, while a value the data determine still moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    pub center: f64,
    pub spread: f64,
}

impl Prior {
    /// The prior's residual (in units of one noise standard deviation) at `x`; `None` where it
    /// does not apply (a non-positive centre or value).
    pub fn z(&self, x: f64) -> Option<f64> {
        (self.center > 0.0 && x > 0.0 && self.spread > 0.0)
            .then(|| (x / self.center).ln() / self.spread)
    }
}

/// Robust noise variance of a measured signal: from its second differences,
/// `σ = 1.4826 · MAD(Δ²y) / √6` (a white sequence's second difference has variance 6σ²; the
/// median ignores the few samples where the event moves the signal).
pub fn noise_variance(y: &[f64]) -> f64 {
    if y.len() < 5 {
        return 0.0;
    }
    let mut d2: Vec<f64> = y.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
    let med = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| a.total_cmp(b));
        v[v.len() / 2]
    };
    let m = med(&mut d2);
    let mut dev: Vec<f64> = d2.iter().map(|d| (d - m).abs()).collect();
    let mad = med(&mut dev);
    (1.4826 * mad).powi(2) / 6.0
}

/// Whether a parameter free in `[lo, hi]` is searched on a log scale: a positive range of a
/// decade or more (the one rule of [`FreeParam::new`]).
pub fn is_log_scale(lo: f64, hi: f64) -> bool {
    lo > 0.0 && hi / lo >= 10.0
}

/// Box coordinate in `[0, 1]` of physical value `x` free in `[lo, hi]`, on the scale the search
/// uses ([`is_log_scale`]): what [`FreeParam::to_unit`] gives, for a rule that has the range but
/// not the parameter.
pub fn box_coordinate(x: f64, lo: f64, hi: f64) -> f64 {
    coordinate(x, lo, hi, is_log_scale(lo, hi))
}

/// Box coordinate of `x` in `[lo, hi]` on a log or a linear scale (clamped into the range).
fn coordinate(x: f64, lo: f64, hi: f64, log: bool) -> f64 {
    let x = crate::bounds::clamp_into(x, lo, hi);
    if log {
        (x / lo).ln() / (hi / lo).ln()
    } else {
        (x - lo) / (hi - lo)
    }
}

impl FreeParam {
    pub fn new(
        path: String,
        r: ParamRef,
        lo: f64,
        hi: f64,
        start: f64,
        unit: &'static str,
    ) -> Self {
        let log = is_log_scale(lo, hi);
        Self {
            path,
            r,
            lo,
            hi,
            log,
            // `resolve` checks the bounds first; unchecked ones leave the start as given.
            start: crate::bounds::clamp_into(start, lo, hi),
            unit,
            prior: None,
        }
    }
    /// The same parameter with a prior.
    pub fn with_prior(self, prior: Option<Prior>) -> Self {
        Self { prior, ..self }
    }
    /// Physical value at box coordinate `u ∈ [0, 1]`.
    pub fn from_unit(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let x = if self.log {
            self.lo * (self.hi / self.lo).powf(u)
        } else {
            self.lo + (self.hi - self.lo) * u
        };
        crate::bounds::clamp_into(x, self.lo, self.hi)
    }
    /// `dx/du` of [`FreeParam::from_unit`] at the physical value `x` it gave: `x ln(hi/lo)` on
    /// a log scale, `hi − lo` on a linear one.
    pub fn dx_du(&self, x: f64) -> f64 {
        if self.log {
            x * (self.hi / self.lo).ln()
        } else {
            self.hi - self.lo
        }
    }
    /// Box coordinate of physical value `x`.
    pub fn to_unit(&self, x: f64) -> f64 {
        coordinate(x, self.lo, self.hi, self.log)
    }
    /// True when `x` lies within 0.1 % of the box width of a bound.
    pub fn at_bound(&self, x: f64) -> bool {
        let u = self.to_unit(x);
        !(0.001..=0.999).contains(&u)
    }
    /// True when `x` lies within 0.1 % of the box width of the upper bound.
    pub fn at_upper_bound(&self, x: f64) -> bool {
        self.to_unit(x) > 0.999
    }
}

/// Σ r², the objective of a residual vector.
pub fn sum_of_squares(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Logistic map ℝ → (0, 1).
pub fn logistic(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// Inverse of [`logistic`], with `u` kept 1e-9 away from 0 and 1.
pub fn logit(u: f64) -> f64 {
    let u = u.clamp(1e-9, 1.0 - 1e-9);
    (u / (1.0 - u)).ln()
}

/// One event's data as the objective uses it.
#[derive(Debug, Clone)]
pub struct EventData {
    pub name: String,
    pub prepared: PreparedEvent,
    /// Measured P and Q (system base), low-passed if the stage asks for it.
    pub p_meas: Vec<f64>,
    pub q_meas: Vec<f64>,
    /// Samples inside the fit window ([`Window::contains`]: the event module's one time
    /// tolerance).
    pub in_window: Vec<bool>,
    /// Measured |V|, and E_fd and X_adI_fd when recorded (low-passed as P and Q), compared by
    /// stages with channels ([`crate::spec::Compare`]).
    pub v_meas: Vec<f64>,
    pub efd_meas: Option<Vec<f64>>,
    pub ifd_meas: Option<Vec<f64>>,
}

/// Sums of squared residuals over an event's window ([`EventData::window_sums`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WindowSums {
    /// Σ ΔP² over the window.
    pub p: f64,
    /// Σ ΔQ² over the window.
    pub q: f64,
    /// Samples in the window.
    pub n: usize,
}

impl WindowSums {
    /// `J = w_p Σ ΔP² + w_q Σ ΔQ²`.
    pub fn j(&self, (wp, wq): (f64, f64)) -> f64 {
        wp * self.p + wq * self.q
    }
}

/// Why an event cannot be prepared or a candidate's residuals cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProblemError {
    /// Fewer than 3 samples in the fit window.
    #[error("event '{event}': fewer than 3 samples in the fit window [{start}, {end}] s")]
    Window { event: String, start: f64, end: f64 },
    /// The measurement's low-pass filter cannot be applied.
    #[error("event '{event}': {msg}")]
    Filter { event: String, msg: String },
    /// The candidate's simulation failed (the engine's error, kept typed: an initialisation
    /// failure and an integration failure are told apart by every front end).
    #[error("{event}: {error}")]
    Simulation {
        event: String,
        error: itaipu_dynamics::simulate::SimError,
    },
    /// The candidate's simulation ran away (|P| or |Q| beyond the divergence bound).
    #[error("{event}: simulation diverged at t = {t:.3} s")]
    Diverged { event: String, t: f64 },
    /// The problem's cancel flag was set.
    #[error("interrupted")]
    Interrupted,
}

impl ProblemError {
    /// A stable name of the variant.
    pub fn kind(&self) -> &'static str {
        match self {
            ProblemError::Window { .. } => "window",
            ProblemError::Filter { .. } => "filter",
            ProblemError::Simulation { .. } => "simulation",
            ProblemError::Diverged { .. } => "diverged",
            ProblemError::Interrupted => "interrupted",
        }
    }
}

impl EventData {
    /// Prepares `event` with the window `window` (default: the event's fit window) and an
    /// optional zero-phase low-pass of the measurement.
    pub fn new(
        event: &Event,
        window: Option<[f64; 2]>,
        lowpass_hz: Option<f64>,
    ) -> Result<Self, ProblemError> {
        let r = &event.record;
        let [a, b] = window.unwrap_or([event.fit.start_s, event.fit.end_s]);
        let window = Window::new(a, b);
        let in_window: Vec<bool> = r.time_s.iter().map(|&t| window.contains(t)).collect();
        if in_window.iter().filter(|w| **w).count() < MIN_SAMPLES {
            return Err(ProblemError::Window {
                event: event.name.clone(),
                start: a,
                end: b,
            });
        }
        let (mut p, mut q) = (r.p_pu.clone(), r.q_pu.clone());
        let mut v = r.v_mag_pu.clone();
        let (mut efd, mut ifd) = (r.efd_pu.clone(), r.ifd_pu.clone());
        if let Some(fc) = lowpass_hz {
            let filter_err = |e: crate::filter::FilterError| ProblemError::Filter {
                event: event.name.clone(),
                msg: e.to_string(),
            };
            let fs = crate::filter::sample_rate(&r.time_s).map_err(filter_err)?;
            let lp = |y: &[f64]| crate::filter::lowpass_zero_phase(y, fs, fc).map_err(filter_err);
            p = lp(&p)?;
            q = lp(&q)?;
            v = lp(&v)?;
            efd = efd.as_deref().map(lp).transpose()?;
            ifd = ifd.as_deref().map(lp).transpose()?;
        }
        Ok(Self {
            name: event.name.clone(),
            prepared: PreparedEvent::new(event),
            p_meas: p,
            q_meas: q,
            in_window,
            v_meas: v,
            efd_meas: efd,
            ifd_meas: ifd,
        })
    }

    /// The measured series of channel `c` as compared (`None`: not recorded, or not a
    /// comparable channel).
    pub fn measured(&self, c: Channel) -> Option<&[f64]> {
        match c {
            Channel::P => Some(&self.p_meas),
            Channel::Q => Some(&self.q_meas),
            Channel::V => Some(&self.v_meas),
            Channel::Efd => self.efd_meas.as_deref(),
            Channel::Ifd => self.ifd_meas.as_deref(),
            Channel::Angle | Channel::Freq => None,
        }
    }

    /// Robust noise variance of the measured channel `c` over the window ([`noise_variance`]),
    /// floored at the variance of its rounding (`q²/12`, `q` the smallest step between
    /// samples: a smoothed, rounded record's second differences are mostly 0); 0 when not
    /// recorded.
    pub fn channel_noise_variance(&self, c: Channel) -> f64 {
        self.measured(c).map_or(0.0, |y| {
            let w: Vec<f64> = y
                .iter()
                .zip(&self.in_window)
                .filter(|(_, w)| **w)
                .map(|(v, _)| *v)
                .collect();
            let q = w
                .windows(2)
                .map(|p| (p[1] - p[0]).abs())
                .filter(|d| *d > 0.0)
                .fold(f64::INFINITY, f64::min);
            let floor = if q.is_finite() { q * q / 12.0 } else { 0.0 };
            noise_variance(&w).max(floor)
        })
    }

    /// Per compared channel, `(channel, Σ Δ², samples)` of simulated outputs `out` over the
    /// window (NaN sums for a channel the record lacks).
    pub fn channel_sums(
        &self,
        out: &ModeOutputs,
        channels: &[Channel],
    ) -> Vec<(Channel, f64, usize)> {
        channels
            .iter()
            .map(|&c| {
                let (Some(sim), Some(meas)) = (out.channel(c), self.measured(c)) else {
                    return (c, f64::NAN, 0);
                };
                let (mut sum, mut n) = (0.0, 0);
                for k in (0..sim.len()).filter(|&k| self.in_window[k]) {
                    sum += (sim[k] - meas[k]).powi(2);
                    n += 1;
                }
                (c, sum, n)
            })
            .collect()
    }

    /// The window's samples `k` with the residuals `(k, P_k − P_meas,k, Q_k − Q_meas,k)` of a
    /// simulated `p`, `q` (the record's samples): what J sums, in one place for the fit's
    /// objective ([`Problem::residuals`]) and its report ([`Self::window_sums`]).
    pub fn window_residuals<'a>(
        &'a self,
        p: &'a [f64],
        q: &'a [f64],
    ) -> impl Iterator<Item = (usize, f64, f64)> + 'a {
        (0..p.len())
            .filter(move |&k| self.in_window[k])
            .map(move |k| (k, p[k] - self.p_meas[k], q[k] - self.q_meas[k]))
    }

    /// The sums of squared residuals of a simulated `p`, `q` over the window
    /// ([`Self::window_residuals`]).
    pub fn window_sums(&self, p: &[f64], q: &[f64]) -> WindowSums {
        let mut s = WindowSums::default();
        for (_, dp, dq) in self.window_residuals(p, q) {
            s.p += dp.powi(2);
            s.q += dq.powi(2);
            s.n += 1;
        }
        s
    }

    /// Number of samples in the window.
    pub fn n_window(&self) -> usize {
        self.in_window.iter().filter(|w| **w).count()
    }

    /// Robust noise variances `(σ²_P, σ²_Q)` of the measured P and Q over the window
    /// ([`noise_variance`]): what weights the datasheet prior, and what the reports show.
    pub fn noise_variances(&self) -> (f64, f64) {
        let take = |y: &[f64]| -> Vec<f64> {
            y.iter()
                .zip(&self.in_window)
                .filter(|(_, w)| **w)
                .map(|(v, _)| *v)
                .collect()
        };
        (
            noise_variance(&take(&self.p_meas)),
            noise_variance(&take(&self.q_meas)),
        )
    }
}

/// Signal weights of an objective.
pub fn objective_weights(objective: Objective, w: Weights) -> (f64, f64) {
    match objective {
        Objective::Pq => (w.p, w.q),
        Objective::Q => (0.0, w.q),
        Objective::P => (w.p, 0.0),
    }
}

/// Integrator used for objective evaluations during the search (swarms and grid scans):
/// Dormand-Prince at rtol 1e-4, atol 1e-5.
///
/// What a search needs is the ranking of candidates; every result it hands on is polished by the
/// local method and re-evaluated on [`accurate_integrator`]. The rule for its tolerance (a noise
/// model): its error in P and Q must be a small fraction of the record's own noise σ, so that it
/// moves a candidate's χ² by a small fraction of that χ² and the ranking the swarm acts on is the
/// record's, not the integrator's (`cargo run --release -p itaipu-calib --example search_error`
/// measures both on a set of records). Its steps are then nearly held by the samples (the
/// played-back input is linear between them): about one step attempt per sample, where a
/// tighter tolerance lets the error control, rather than the samples, set the step.
///
/// The step budget is 25 000 steps, about 15 × what a 25 s event at 60 samples/s takes, so a
/// candidate that chatters on a limiter is failed and penalised rather than simulated for
/// seconds. (A budget proportional to the record would also fail the near-degenerate machines,
/// X'_d → X''_d → X_l, that a generator stage passes through on its way to a good fit.) A swarm
/// all of whose candidates are that costly gives up instead
/// (`fit::search::TOO_COSTLY_STEPS_PER_SAMPLE`).
pub fn search_integrator() -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options::search()),
    }
}

/// Integrator of a diagnosis re-fit's searches (swarms and grid scans) with
/// [`crate::diagnose::DiagnoseOptions::refit_over_samples`]: [`search_integrator`] stepping over
/// the samples inside a smoothed input's spline ([`Dopri5Options::soft_knots`]), observing them
/// on the steps' dense output.
///
/// The rule that allows it: a record low-passed at `f_c` well below its Nyquist frequency is
/// band-limited, so the spline through its samples follows it (its error falls as `(f_c/f_s)⁴`,
/// the line's as `(f_c/f_s)²`) and has continuous first and second derivatives at them; the
/// steps are then set by the error control on the unit's own dynamics instead of by the sample
/// spacing. Its cost: its J is not the line's (the spline departs from the line between samples
/// where the angle swings after a fault), and the χ² a re-fit reports is taken on the line, so a
/// search that ranks on the spline and polishes on the line can end in another valley: an
/// option, off by default.
///
/// Why a calibration's swarm keeps [`search_integrator`]: its step budget is a multiple of what
/// a playback landing on every sample takes, set to fail the stiff and chattering candidates a
/// swarm over the whole box meets (near-degenerate machines). Stepping over the samples lowers
/// every candidate's step count, the stiff ones' included, so the same budget no longer fails
/// them; a budget for this integrator would have to be derived again from its own step counts.
pub fn refit_search_integrator() -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options {
            soft_knots: true,
            ..Dopri5Options::search()
        }),
    }
}

/// Integrator used for reported objectives and the Fisher matrix (tight tolerances).
///
/// The step budget (200 000 steps, about 40 × what a 30 s event needs at these tolerances) fails
/// a degenerate candidate (say X'_d → X''_d → X_l, where the machine's flux equations become
/// singular and the step collapses) in about a second instead of minutes.
pub fn accurate_integrator() -> SimOptions {
    SimOptions {
        method: Method::Dopri5(Dopri5Options {
            rtol: 1e-9,
            atol: 1e-10,
            h_max: 0.02,
            max_steps: 200_000,
            ..Default::default()
        }),
    }
}

/// One event's simulated P and Q at the record's samples ([`Problem::simulate`]).
pub type SimulatedPq = (Vec<f64>, Vec<f64>);

/// One event's watched playback in [`Problem::residuals_until`] as the residuals would judge it:
/// a failed simulation, or a sample that ran away (at time `diverged`: the watch stopped there),
/// is the candidate's error; otherwise the outputs, or `None` when the watch stopped the
/// playback at the bound.
fn settle<T>(
    ev: &EventData,
    watched: Result<Option<T>, itaipu_dynamics::simulate::SimError>,
    diverged: Option<f64>,
) -> Result<Option<T>, ProblemError> {
    let watched = watched.map_err(|error| ProblemError::Simulation {
        event: ev.name.clone(),
        error,
    })?;
    if let Some(t) = diverged {
        return Err(ProblemError::Diverged {
            event: ev.name.clone(),
            t,
        });
    }
    Ok(watched)
}

/// What a bounded evaluation ([`Problem::cost_bounded`]) found.
enum Below {
    /// The whole residuals (their sum may still be at or above the bound, within the margin).
    Residuals(Vec<f64>),
    /// The playback stopped: the sum of squares reached so far, past the bound.
    Stopped(f64),
    /// The candidate failed (counted and logged).
    Failed,
}

/// Relative margin by which a partial sum of squares must pass the bound before
/// [`Problem::cost_bounded`] stops a playback: summed in another order than the objective, the
/// two may differ by rounding, at most about `n·ε` relative for `n` terms (2e-11 for 10⁵ samples
/// of two channels); 1e-9 leaves a hundredfold margin, and costs nothing measurable (a
/// candidate that close to its particle's best is rare and simulated to the end).
const STOP_MARGIN: f64 = 1e-9;

/// Largest |P| or |Q| [pu] a sane simulation produces; beyond it a candidate has diverged.
const DIVERGED_PU: f64 = 100.0;
/// Failure messages kept (all of them up to this many, so that the sorted first few are the same
/// whatever order threads ran in).
const FAILURE_LOG: usize = 10_000;
/// Failure messages shown in a report.
pub const FAILURES_SHOWN: usize = 20;

/// The least-squares problem of one stage.
pub struct Problem {
    /// The unit with every non-free parameter at its value.
    pub unit: Unit,
    pub free: Vec<FreeParam>,
    pub events: Vec<EventData>,
    /// (w_p, w_q).
    pub weights: (f64, f64),
    /// Finite cost given to a candidate that fails ([`FAILURE_PENALTY`]).
    pub penalty: f64,
    /// Tied parameters `(from, to)`: `to` takes `from`'s value in every candidate (e.g. a
    /// two-mass shaft's generator inertia follows `machine.h`).
    pub ties: Vec<(ParamRef, ParamRef)>,
    /// Variance of one measured residual that scales the priors' residuals ([`Prior`]);
    /// 0 = no prior term.
    pub prior_weight: f64,
    /// Set from outside (an interrupt) to make every later evaluation fail at once, without
    /// simulating: the search then runs out in moments and the caller discards its result.
    pub cancel: Option<Arc<AtomicBool>>,
    /// A stage with a playback mode or channels: the residuals are `√w_c Δc` over the compared
    /// channels in that mode ([`Problem::residuals`]); `None`: the phasor P and Q of `weights`.
    pub compare: Option<Compare>,
    evaluations: AtomicUsize,
    /// The integration step attempts of the bounded evaluations ([`Problem::attempts`]).
    attempts: AtomicU64,
    failures: AtomicUsize,
    failure_log: Mutex<Vec<String>>,
}

/// The cost of a candidate that fails to initialise or integrate: finite, so that the swarm
/// and the line searches can compare and interpolate it, and far above any objective a record
/// can produce (a diagnosis χ² normalised by the noise variance reaches 1e6-1e7 on a record
/// whose model misses an effect by a few percent of P; a failure must never look better).
pub const FAILURE_PENALTY: f64 = 1e30;

impl Problem {
    pub fn new(
        unit: Unit,
        free: Vec<FreeParam>,
        events: Vec<EventData>,
        weights: (f64, f64),
    ) -> Self {
        Self {
            unit,
            free,
            events,
            weights,
            penalty: FAILURE_PENALTY,
            ties: Vec::new(),
            prior_weight: 0.0,
            cancel: None,
            compare: None,
            evaluations: AtomicUsize::new(0),
            attempts: AtomicU64::new(0),
            failures: AtomicUsize::new(0),
            failure_log: Mutex::new(Vec::new()),
        }
    }

    /// Whether the run was interrupted ([`Problem::cancel`]).
    pub fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }

    /// Number of free parameters.
    pub fn dim(&self) -> usize {
        self.free.len()
    }

    /// Physical values at box coordinates `u`.
    pub fn from_unit(&self, u: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .zip(u)
            .map(|(f, u)| f.from_unit(*u))
            .collect()
    }
    /// Box coordinates of physical values `x`.
    pub fn to_unit(&self, x: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .zip(x)
            .map(|(f, x)| f.to_unit(*x))
            .collect()
    }
    /// Physical values at unbounded coordinates `z`.
    pub fn from_z(&self, z: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .zip(z)
            .map(|(f, z)| f.from_unit(logistic(*z)))
            .collect()
    }
    /// Starting values.
    pub fn start(&self) -> Vec<f64> {
        self.free.iter().map(|f| f.start).collect()
    }

    /// The unit with the free parameters at `x`.
    pub fn unit_at(&self, x: &[f64]) -> Unit {
        let mut u = self.unit.clone();
        for (f, v) in self.free.iter().zip(x) {
            u.set(f.r, *v);
        }
        for &(from, to) in &self.ties {
            let v = u.get(from);
            u.set(to, v);
        }
        u
    }

    /// Weighted residual vector `[√w_p ΔP, √w_q ΔQ]` over every event's window samples
    /// (only the signals with a non-zero weight), then the priors' residuals
    /// ([`Problem::prior_residuals`]).
    ///
    /// With [`Problem::compare`] the residuals are `√w_c (c_sim − c_meas)` per window sample and
    /// compared channel (in channel order within a sample) in that playback mode, then the
    /// priors'.
    pub fn residuals(&self, x: &[f64], sim: &SimOptions) -> Result<Vec<f64>, ProblemError> {
        self.residuals_each(x, &vec![sim; self.events.len()])
    }

    /// [`Problem::residuals`] with event `i` simulated on `sims[i]` (each event's replay of its
    /// own logged steps, [`Problem::residuals_with_steps`]).
    pub fn residuals_each(
        &self,
        x: &[f64],
        sims: &[&SimOptions],
    ) -> Result<Vec<f64>, ProblemError> {
        if self.compare.is_some() {
            let outs = self.simulate_outputs_each(x, sims)?;
            return self.residuals_from_outputs(x, &outs);
        }
        let pq = self.simulate_each(x, sims)?;
        self.residuals_from(x, &pq)
    }

    /// The residuals at `x` simulated on Dormand-Prince `opts` (counted as an evaluation, a
    /// failure logged), and per event a [`Method::Replay`] of the steps its simulation took:
    /// residuals replayed on those steps at nearby parameters ([`Problem::residuals_each`])
    /// differ from each other smoothly, without the step-size noise of two adaptive runs.
    pub fn residuals_with_steps(
        &self,
        x: &[f64],
        opts: &Dopri5Options,
    ) -> Option<(Vec<f64>, Vec<SimOptions>)> {
        let logs: Vec<StepLog> = self.events.iter().map(|_| StepLog::default()).collect();
        let sims: Vec<SimOptions> = logs
            .iter()
            .map(|log| SimOptions {
                method: Method::Dopri5Logged(opts.clone(), log.clone()),
            })
            .collect();
        let refs: Vec<&SimOptions> = sims.iter().collect();
        self.evaluations
            .fetch_add(self.events.len(), Ordering::Relaxed);
        match self.residuals_each(x, &refs) {
            Ok(r) => Some((
                r,
                logs.iter()
                    .map(|log| SimOptions {
                        method: Method::Replay(log.times()),
                    })
                    .collect(),
            )),
            Err(msg) => {
                self.record_failure(x, msg.to_string());
                None
            }
        }
    }

    /// [`Problem::residuals_with_steps`] for a caller that needs them only when their sum of
    /// squares is below `bound` (a local method's trial step against its current point):
    /// `None` also when the playback stopped because it could not end below ([`Problem::cost_bounded`]
    /// stops the same way, and with the same margin); otherwise that function's result, bit for
    /// bit, whose sum the caller still compares (it may lie within the margin above `bound`).
    /// A stopped candidate is counted as a simulation and is not a failure.
    pub fn residuals_with_steps_below(
        &self,
        x: &[f64],
        opts: &Dopri5Options,
        bound: f64,
    ) -> Option<(Vec<f64>, Vec<SimOptions>)> {
        let logs: Vec<StepLog> = self.events.iter().map(|_| StepLog::default()).collect();
        let sims: Vec<SimOptions> = logs
            .iter()
            .map(|log| SimOptions {
                method: Method::Dopri5Logged(opts.clone(), log.clone()),
            })
            .collect();
        let refs: Vec<&SimOptions> = sims.iter().collect();
        match self.residuals_below(x, &refs, bound) {
            Below::Residuals(r) => Some((
                r,
                logs.iter()
                    .map(|log| SimOptions {
                        method: Method::Replay(log.times()),
                    })
                    .collect(),
            )),
            Below::Stopped(_) | Below::Failed => None,
        }
    }

    /// [`Problem::residuals_logged`] for a caller that needs them only when their sum of squares
    /// is below `bound`, as [`Problem::residuals_with_steps_below`].
    pub fn residuals_logged_below(
        &self,
        x: &[f64],
        sim: &SimOptions,
        bound: f64,
    ) -> Option<Vec<f64>> {
        match self.residuals_below(x, &vec![sim; self.events.len()], bound) {
            Below::Residuals(r) => Some(r),
            Below::Stopped(_) | Below::Failed => None,
        }
    }

    /// Every event simulated in the stage's playback mode ([`Problem::compare`]; the phasor
    /// playback without) at physical values `x`: all the channels at the record's samples.
    pub fn simulate_outputs(
        &self,
        x: &[f64],
        sim: &SimOptions,
    ) -> Result<Vec<ModeOutputs>, ProblemError> {
        self.simulate_outputs_each(x, &vec![sim; self.events.len()])
    }

    fn simulate_outputs_each(
        &self,
        x: &[f64],
        sims: &[&SimOptions],
    ) -> Result<Vec<ModeOutputs>, ProblemError> {
        if self.cancelled() {
            return Err(ProblemError::Interrupted);
        }
        let mode = self.compare.as_ref().map(|c| c.mode).unwrap_or_default();
        let unit = self.unit_at(x);
        self.events
            .iter()
            .zip(sims)
            .map(|(ev, sim)| {
                simulate_mode(&unit, &ev.prepared, mode, sim).map_err(|error| {
                    ProblemError::Simulation {
                        event: ev.name.clone(),
                        error,
                    }
                })
            })
            .collect()
    }

    /// The residuals of [`Problem::compare`]'s channels from the events' simulated outputs.
    pub fn residuals_from_outputs(
        &self,
        x: &[f64],
        outs: &[ModeOutputs],
    ) -> Result<Vec<f64>, ProblemError> {
        let Some(cmp) = &self.compare else {
            let pq: Vec<SimulatedPq> = outs.iter().map(|o| (o.p.clone(), o.q.clone())).collect();
            return self.residuals_from(x, &pq);
        };
        let mut r = Vec::new();
        for (ev, out) in self.events.iter().zip(outs) {
            let series: Vec<(f64, &[f64], &[f64])> = cmp
                .weights
                .iter()
                .filter_map(|&(c, w)| Some((w.sqrt(), out.channel(c)?, ev.measured(c)?)))
                .collect();
            for k in (0..ev.in_window.len()).filter(|&k| ev.in_window[k]) {
                for &(sw, sim, meas) in &series {
                    if !(sim[k].abs() < DIVERGED_PU) {
                        return Err(ProblemError::Diverged {
                            event: ev.name.clone(),
                            t: ev.prepared.input.time_s[k],
                        });
                    }
                    r.push(sw * (sim[k] - meas[k]));
                }
            }
        }
        r.extend(self.prior_residuals(x));
        Ok(r)
    }

    /// The simulated P and Q of every event at physical values `x` (the record's samples; in
    /// the stage's playback mode with [`Problem::compare`]).
    pub fn simulate(&self, x: &[f64], sim: &SimOptions) -> Result<Vec<SimulatedPq>, ProblemError> {
        self.simulate_each(x, &vec![sim; self.events.len()])
    }

    fn simulate_each(
        &self,
        x: &[f64],
        sims: &[&SimOptions],
    ) -> Result<Vec<SimulatedPq>, ProblemError> {
        if self.compare.is_some() {
            return Ok(self
                .simulate_outputs_each(x, sims)?
                .into_iter()
                .map(|o| (o.p, o.q))
                .collect());
        }
        if self.cancelled() {
            return Err(ProblemError::Interrupted);
        }
        let mut unit = self.unit_at(x);
        self.events
            .iter()
            .zip(sims)
            .map(|(ev, sim)| {
                simulate_pq(&mut unit, &ev.prepared, sim).map_err(|error| {
                    ProblemError::Simulation {
                        event: ev.name.clone(),
                        error,
                    }
                })
            })
            .collect()
    }

    /// The residuals at physical values `x` from the events' simulated P and Q `pq` (as
    /// [`Self::simulate`] gives them): another problem over the same events with other windows
    /// (a fit/held-out split) reads the same simulation.
    pub fn residuals_from(&self, x: &[f64], pq: &[SimulatedPq]) -> Result<Vec<f64>, ProblemError> {
        let (sp, sq) = (self.weights.0.sqrt(), self.weights.1.sqrt());
        let mut r = Vec::new();
        for (ev, (p, q)) in self.events.iter().zip(pq) {
            for (k, dp, dq) in ev.window_residuals(p, q) {
                if !(p[k].abs() < DIVERGED_PU && q[k].abs() < DIVERGED_PU) {
                    return Err(ProblemError::Diverged {
                        event: ev.name.clone(),
                        t: ev.prepared.input.time_s[k],
                    });
                }
                if sp > 0.0 {
                    r.push(sp * dp);
                }
                if sq > 0.0 {
                    r.push(sq * dq);
                }
            }
        }
        r.extend(self.prior_residuals(x));
        Ok(r)
    }

    /// Whether [`Problem::sensitivity_jacobian_x`] can take this problem's Jacobian: the
    /// phasor playback (P and Q, or a [`Compare`] of its channels), not another mode.
    pub fn has_sensitivities(&self) -> bool {
        !matches!(&self.compare, Some(c) if c.mode != itaipu_dynamics::mode::PlaybackMode::Phasor)
    }

    /// The Jacobian of [`Problem::residuals`] at box point `u` with respect to the box
    /// coordinates ([`Problem::sensitivity_jacobian_x`] chained with `dx/du`).
    pub fn sensitivity_jacobian(&self, u: &[f64], sims: &[&SimOptions]) -> Option<Vec<Vec<f64>>> {
        let x = self.from_unit(u);
        let mut cols = self.sensitivity_jacobian_x(&x, sims)?;
        for ((c, f), &xv) in cols.iter_mut().zip(&self.free).zip(&x) {
            let dxdu = f.dx_du(xv);
            c.iter_mut().for_each(|v| *v *= dxdu);
        }
        Some(cols)
    }

    /// The Jacobian of [`Problem::residuals`] at physical values `x`, one column per free
    /// parameter, by forward sensitivities ([`itaipu_dynamics::sens`]): each event's playback on
    /// `sims[i]` (a replay of the steps the residuals' simulation took, or the options
    /// themselves) with `∂P/∂p`, `∂Q/∂p` integrated along (the passes of
    /// [`itaipu_dynamics::sens::LANES`] parameters in parallel), the tied parameters moving
    /// with their source, the priors' rows analytically. Exact for the discretised playback,
    /// where differences carry their step's truncation and, between adaptive runs, the
    /// integrator's noise. The phasor playback's compared field channels (E_fd, X_ad I_fd,
    /// [`Problem::compare`]) come out of the same passes. `None` when the stage plays back in
    /// another mode, a block has no dual equations or a simulation fails: the caller then takes
    /// differences.
    pub fn sensitivity_jacobian_x(&self, x: &[f64], sims: &[&SimOptions]) -> Option<Vec<Vec<f64>>> {
        if !self.has_sensitivities() || self.cancelled() {
            return None;
        }
        let unit = self.unit_at(x);
        // Every free parameter and the parameters tied to it move together.
        let mut refs: Vec<ParamRef> = Vec::new();
        let groups: Vec<Vec<usize>> = self
            .free
            .iter()
            .map(|f| {
                std::iter::once(f.r)
                    .chain(self.ties.iter().filter(|t| t.0 == f.r).map(|t| t.1))
                    .map(|r| {
                        refs.iter().position(|&q| q == r).unwrap_or_else(|| {
                            refs.push(r);
                            refs.len() - 1
                        })
                    })
                    .collect()
            })
            .collect();
        let (sp, sq) = (self.weights.0.sqrt(), self.weights.1.sqrt());
        let n = self.free.len();
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); n];
        // Every event's passes (LANES parameters each) in parallel.
        let lanes = itaipu_dynamics::sens::LANES;
        let jobs: Vec<(usize, &[ParamRef])> = (0..self.events.len())
            .flat_map(|e| refs.chunks(lanes).map(move |c| (e, c)))
            .collect();
        let mut passes: Vec<Option<itaipu_dynamics::sens::PqSensitivities>> = jobs
            .par_iter()
            .map(|&(e, chunk)| {
                let ev = &self.events[e];
                itaipu_dynamics::sens::simulate_pq_sensitivities(
                    &unit,
                    &ev.prepared,
                    chunk,
                    sims[e],
                )
                .ok()
            })
            .collect();
        self.evaluations.fetch_add(jobs.len(), Ordering::Relaxed);
        for (e, (ev, _)) in self.events.iter().zip(sims).enumerate() {
            // The event's passes, their columns in `refs` order.
            let mut s = itaipu_dynamics::sens::PqSensitivities::default();
            for (&(je, _), pass) in jobs.iter().zip(passes.iter_mut()) {
                if je != e {
                    continue;
                }
                s.extend(pass.take()?);
            }
            if s.p.is_empty() {
                return None;
            }
            if let Some(cmp) = &self.compare {
                // The rows of [`Problem::residuals_from_outputs`]: per window sample, each
                // compared channel the event records, weighted by √w.
                let chans: Vec<WeightedChannel> = cmp
                    .weights
                    .iter()
                    .filter(|(c, _)| ev.measured(*c).is_some())
                    .map(|&(c, w)| {
                        let (v, d) = match c {
                            Channel::P => (&s.p, &s.dp),
                            Channel::Q => (&s.q, &s.dq),
                            Channel::Efd => (&s.efd, &s.defd),
                            Channel::Ifd => (&s.ifd, &s.difd),
                            _ => return None,
                        };
                        (!v.is_empty()).then_some((w.sqrt(), v.as_slice(), d.as_slice()))
                    })
                    .collect::<Option<_>>()?;
                for k in (0..ev.in_window.len()).filter(|&k| ev.in_window[k]) {
                    for &(sw, v, d) in &chans {
                        if !(v[k].abs() < DIVERGED_PU) {
                            return None;
                        }
                        for (j, g) in groups.iter().enumerate() {
                            cols[j].push(sw * g.iter().fold(0.0, |a, &i| a + d[i][k]));
                        }
                    }
                }
                continue;
            }
            for (k, _, _) in ev.window_residuals(&s.p, &s.q) {
                if !(s.p[k].abs() < DIVERGED_PU && s.q[k].abs() < DIVERGED_PU) {
                    return None;
                }
                for (j, g) in groups.iter().enumerate() {
                    let (dp, dq) = g
                        .iter()
                        .fold((0.0, 0.0), |(a, b), &i| (a + s.dp[i][k], b + s.dq[i][k]));
                    if sp > 0.0 {
                        cols[j].push(sp * dp);
                    }
                    if sq > 0.0 {
                        cols[j].push(sq * dq);
                    }
                }
            }
        }
        // The priors' rows: d(σ ln(x/c)/spread)/dx = σ/(x spread), in the order of
        // [`Problem::prior_residuals`].
        if self.prior_weight > 0.0 {
            let sw = self.prior_weight.sqrt();
            for (i, (f, &xv)) in self.free.iter().zip(x).enumerate() {
                if let Some(p) = f.prior.filter(|p| p.z(xv).is_some()) {
                    for (j, c) in cols.iter_mut().enumerate() {
                        c.push(if i == j { sw / (xv * p.spread) } else { 0.0 });
                    }
                }
            }
        }
        cols.iter()
            .all(|c| c.iter().all(|v| v.is_finite()))
            .then_some(cols)
    }

    /// Variance of one weighted residual of the measured events: the mean over the signals
    /// with a non-zero weight of `w · σ²`, σ² from [`noise_variance`] over each event's window.
    pub fn measured_noise_variance(&self) -> f64 {
        if let Some(cmp) = &self.compare {
            let (mut sum, mut n) = (0.0, 0usize);
            for ev in &self.events {
                for &(c, w) in &cmp.weights {
                    sum += w * ev.channel_noise_variance(c);
                    n += 1;
                }
            }
            return if n == 0 { 0.0 } else { sum / n as f64 };
        }
        let (wp, wq) = self.weights;
        let (mut sum, mut n) = (0.0, 0usize);
        for ev in &self.events {
            let (vp, vq) = ev.noise_variances();
            if wp > 0.0 {
                sum += wp * vp;
                n += 1;
            }
            if wq > 0.0 {
                sum += wq * vq;
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            sum / n as f64
        }
    }

    /// The priors' residuals at `x` (empty without a prior weight).
    pub fn prior_residuals(&self, x: &[f64]) -> Vec<f64> {
        if !(self.prior_weight > 0.0) {
            return vec![];
        }
        let s = self.prior_weight.sqrt();
        self.free
            .iter()
            .zip(x)
            .filter_map(|(f, v)| f.prior.and_then(|p| p.z(*v)).map(|z| s * z))
            .collect()
    }

    /// The lowest objective among `points` (physical values, evaluated in parallel) and its
    /// index, the first one on ties, so the choice does not depend on thread timing.
    pub fn best_of(&self, points: &[Vec<f64>], sim: &SimOptions) -> (f64, usize) {
        self.best_of_below(points, sim, f64::INFINITY)
    }

    /// [`Problem::best_of`] for a caller that uses the result only when it is below `bound` (a
    /// grid scan against its start): each point's playback stops once it cannot end below
    /// ([`Problem::cost_bounded`]). When some point ends below `bound` the result is
    /// [`Problem::best_of`]'s, bit for bit (a stopped point scores above `bound`, so above the
    /// best); otherwise it is some value at or above `bound`.
    pub fn best_of_below(&self, points: &[Vec<f64>], sim: &SimOptions, bound: f64) -> (f64, usize) {
        let costs: Vec<f64> = points
            .par_iter()
            .map(|x| self.cost_bounded(x, sim, bound))
            .collect();
        costs.into_iter().enumerate().fold(
            (f64::INFINITY, 0),
            |a, (i, c)| if c < a.0 { (c, i) } else { a },
        )
    }

    /// The objective at physical values `x`; the penalty (counted and logged) on failure.
    pub fn cost(&self, x: &[f64], sim: &SimOptions) -> f64 {
        self.residuals_logged(x, sim)
            .map_or(self.penalty, |r| sum_of_squares(&r))
    }

    /// [`Problem::cost`] for a caller that needs the objective only when it is below `bound`
    /// (a swarm's particle against its personal best, [`crate::pso::minimize_bounded`]): the
    /// objective, bit for bit [`Problem::cost`]'s, when the candidate ends below `bound`;
    /// otherwise some value at or above `bound`.
    ///
    /// The objective is a sum of squares in time order, event after event, plus the priors'
    /// squares: once the priors and the samples simulated so far reach `bound`, the rest of the
    /// playback cannot bring the candidate below it, and it stops there. It stops only when
    /// `bound` is at most the penalty: a candidate that would fail later scores the penalty,
    /// which must not be below `bound` either. The partial sum is taken in another order than
    /// [`Problem::cost`]'s, so it must pass `bound` by [`STOP_MARGIN`] (relative) to stop: a
    /// candidate whose objective is within rounding of the bound is simulated to the end. A
    /// stopped candidate is counted as a simulation; a failure it would have met later is not
    /// seen (nor logged).
    pub fn cost_bounded(&self, x: &[f64], sim: &SimOptions, bound: f64) -> f64 {
        match self.residuals_below(x, &vec![sim; self.events.len()], bound) {
            Below::Residuals(r) => sum_of_squares(&r),
            Below::Stopped(partial) => partial,
            Below::Failed => self.penalty,
        }
    }

    /// The one bounded evaluation behind [`Problem::cost_bounded`],
    /// [`Problem::residuals_logged_below`] and [`Problem::residuals_with_steps_below`]: counted
    /// as an evaluation, a failure logged, the playback stopped once its partial sum passes
    /// `bound` by [`STOP_MARGIN`] where `bound` is at most the penalty (whole otherwise, and
    /// when the problem is cancelled: [`Problem::residuals_logged_each`]'s path).
    fn residuals_below(&self, x: &[f64], sims: &[&SimOptions], bound: f64) -> Below {
        // The candidate's playbacks run on this thread, one after the other.
        let a0 = itaipu_dynamics::integrate::dopri5::attempts_on_this_thread();
        let below = self.residuals_below_run(x, sims, bound);
        let spent = itaipu_dynamics::integrate::dopri5::attempts_on_this_thread() - a0;
        self.attempts.fetch_add(spent, Ordering::Relaxed);
        below
    }

    /// [`Problem::residuals_below`] without the work count.
    fn residuals_below_run(&self, x: &[f64], sims: &[&SimOptions], bound: f64) -> Below {
        if !(bound <= self.penalty) || self.cancelled() {
            return match self.residuals_logged_each(x, sims) {
                Some(r) => Below::Residuals(r),
                None => Below::Failed,
            };
        }
        self.evaluations
            .fetch_add(self.events.len(), Ordering::Relaxed);
        match self.residuals_until(x, sims, bound * (1.0 + STOP_MARGIN)) {
            Ok(Ok(r)) => Below::Residuals(r),
            Ok(Err(partial)) => Below::Stopped(partial),
            Err(msg) => {
                self.record_failure(x, msg.to_string());
                Below::Failed
            }
        }
    }

    /// The residuals at `x` ([`Problem::residuals`], bit for bit), or `Err(partial)`, the sum of
    /// squares reached, once it reaches `stop_at` ([`Problem::cost_bounded`]).
    fn residuals_until(
        &self,
        x: &[f64],
        sims: &[&SimOptions],
        stop_at: f64,
    ) -> Result<Result<Vec<f64>, f64>, ProblemError> {
        let mut partial = sum_of_squares(&self.prior_residuals(x));
        if partial >= stop_at {
            return Ok(Err(partial));
        }
        // The first sample that ran away, as the residuals would report it.
        let mut diverged: Option<f64> = None;
        let unit = self.unit_at(x);
        if let Some(cmp) = &self.compare {
            let mut outs = Vec::with_capacity(self.events.len());
            for (ev, sim) in self.events.iter().zip(sims) {
                let series: Vec<(f64, Channel, &[f64])> = cmp
                    .weights
                    .iter()
                    .filter_map(|&(c, w)| Some((w, c, ev.measured(c)?)))
                    .collect();
                let watched = simulate_mode_watched(&unit, &ev.prepared, cmp.mode, sim, |k, o| {
                    if !ev.in_window[k] {
                        return true;
                    }
                    for &(w, c, meas) in &series {
                        let Some(s) = o.channel(c) else { continue };
                        if !(s[k].abs() < DIVERGED_PU) {
                            diverged = Some(ev.prepared.input.time_s[k]);
                            return false;
                        }
                        partial += w * (s[k] - meas[k]).powi(2);
                    }
                    partial < stop_at
                });
                match settle(ev, watched, diverged)? {
                    Some(o) => outs.push(o),
                    None => return Ok(Err(partial)),
                }
            }
            return self.residuals_from_outputs(x, &outs).map(Ok);
        }
        let (wp, wq) = self.weights;
        let mut unit = unit;
        let mut pq = Vec::with_capacity(self.events.len());
        for (ev, sim) in self.events.iter().zip(sims) {
            let watched = simulate_pq_watched(&mut unit, &ev.prepared, sim, |k, p, q| {
                if !ev.in_window[k] {
                    return true;
                }
                if !(p.abs() < DIVERGED_PU && q.abs() < DIVERGED_PU) {
                    diverged = Some(ev.prepared.input.time_s[k]);
                    return false;
                }
                partial += wp * (p - ev.p_meas[k]).powi(2) + wq * (q - ev.q_meas[k]).powi(2);
                partial < stop_at
            });
            match settle(ev, watched, diverged)? {
                Some(s) => pq.push(s),
                None => return Ok(Err(partial)),
            }
        }
        self.residuals_from(x, &pq).map(Ok)
    }

    /// The residuals at physical values `x`, counted as an evaluation; `None` (the failure
    /// counted and logged) when the candidate fails.
    pub fn residuals_logged(&self, x: &[f64], sim: &SimOptions) -> Option<Vec<f64>> {
        self.residuals_logged_each(x, &vec![sim; self.events.len()])
    }

    /// [`Problem::residuals_logged`] with event `i` simulated on `sims[i]`.
    pub fn residuals_logged_each(&self, x: &[f64], sims: &[&SimOptions]) -> Option<Vec<f64>> {
        self.evaluations
            .fetch_add(self.events.len(), Ordering::Relaxed);
        match self.residuals_each(x, sims) {
            Ok(r) => Some(r),
            Err(msg) => {
                self.record_failure(x, msg.to_string());
                None
            }
        }
    }

    fn record_failure(&self, x: &[f64], msg: String) {
        self.failures.fetch_add(1, Ordering::Relaxed);
        // A poisoned lock (a panic elsewhere while holding it) still holds the log.
        let mut log = self
            .failure_log
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        if log.len() < FAILURE_LOG {
            let at: Vec<String> = self
                .free
                .iter()
                .zip(x)
                .map(|(f, v)| format!("{}={v:.4}", f.path))
                .collect();
            log.push(format!("{msg} [{}]", at.join(", ")));
        }
    }

    /// The adaptive integration step attempts (accepted and rejected) the bounded evaluations
    /// ([`Problem::cost_bounded`]: the swarms; the local method's trial steps) have made so far:
    /// their work, which [`crate::fit::search`] compares with the samples they played.
    pub fn attempts(&self) -> u64 {
        self.attempts.load(Ordering::Relaxed)
    }

    /// Samples one playback of every event lands on (the knots of the played-back input).
    pub fn samples(&self) -> usize {
        self.events
            .iter()
            .map(|e| e.prepared.input.time_s.len())
            .sum()
    }

    /// Simulations run so far (one per event per objective evaluation).
    pub fn simulations(&self) -> usize {
        self.evaluations.load(Ordering::Relaxed)
    }
    /// Failed candidates so far.
    pub fn failures(&self) -> usize {
        self.failures.load(Ordering::Relaxed)
    }
    /// The first failure messages in sorted order (the order threads ran in does not show).
    pub fn failure_messages(&self) -> Vec<String> {
        let mut v = self
            .failure_log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        v.sort();
        v.truncate(FAILURES_SHOWN);
        v
    }
}

/// A compared channel's weight, its measured series and its simulated outputs.
type WeightedChannel<'a> = (f64, &'a [f64], &'a [Vec<f64>]);
