//! Adaptive Dormand-Prince 5(4) with FSAL, PI step control and dense output.
//!
//! **Method.** The explicit 7-stage embedded pair of Dormand & Prince (1980), coefficients as in
//! Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.5, Table 5.2 and the Fortran code `dopri5`.
//! The fifth-order result is propagated (local extrapolation); the seventh stage is evaluated at
//! the new point, so it is the first stage of the next step (FSAL: six evaluations per step).
//!
//! **Error norm** (*Solving ODEs I*, (4.11)): with `e = h·Σ eᵢ·kᵢ` the difference between the
//! fifth- and fourth-order results,
//! `err = sqrt( (1/n) Σᵢ (eᵢ / (atol + rtol·max(|x0ᵢ|, |x1ᵢ|)))² )`; the step is accepted if
//! `err <= 1`.
//!
//! **Step control**: the PI controller ("Lund stabilisation") of the `dopri5` code (see also
//! Hairer & Wanner, *Solving ODEs II*, §IV.2). After an accepted step
//! `h_new = h · clamp(0.9 · err^-(0.2 - 0.75β) · err_old^β, 0.2, 10)` with `β = 0.04` and
//! `err_old` the error of the previous accepted step (at least `1e-4`); the step may not grow
//! right after a rejection; `h <= h_max`. After a rejection `h_new = h · max(0.2, 0.9 ·
//! err^-(0.2 - 0.75β))` (a non-finite `err` gives `0.2·h`). With `h_init == 0` the first step is
//! Hairer's `hinit` (*Solving ODEs I*, §II.4, "Starting step size").
//!
//! **Knots.** A step that would pass the next knot (or stop within 1 % of it) is cut to end on
//! it. Such a shortened step says nothing about the feasible step size, so when it is accepted
//! the controller keeps the unshortened suggestion (unless the new one is larger) and does not
//! update `err_old`. The right-hand side is continuous at knots, so FSAL carries across them; only
//! an event forces a fresh evaluation of `f`.
//!
//! **Dense output** (*Solving ODEs I*, §II.6, and `contd5` in `dopri5`): for `θ ∈ [0, 1]`,
//! `x(t0 + θh) ≈ x0 + θ(Δ + (1-θ)(b + θ(Δ - h·k7 - b + (1-θ)·h·Σ dᵢkᵢ)))`, with
//! `Δ = x1 - x0` and `b = h·k1 - Δ`. It is of order four (local error `O(h⁵)`), continuous, and
//! used to locate events; the step is then re-taken with the event time as its end and accepted
//! without error control.

use super::{begin, check_finite, Dopri5Options, Events, GoOn, OdeSystem, SolveError, Stats};

// Nodes c_i and coefficients a_ij (row s holds a_s1..a_s,s-1; row 6 is the fifth-order weights b).
const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
/// Error weights `b_i - b̂_i` (fifth minus fourth order).
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];
/// Dense-output weights `d_i` of `contd5`.
const D: [f64; 7] = [
    -12715105075.0 / 11282082432.0,
    0.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
];

const BETA: f64 = 0.04;
const SAFETY: f64 = 0.9;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 10.0;

/// Adaptive Dormand-Prince 5(4) driver (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Dopri5 {
    opts: Dopri5Options,
}

impl Dopri5 {
    /// Checks the options: `rtol` finite and `> 10·ε`, `atol` finite and `>= 0`, `h_max > 0`
    /// (may be infinite), `h_init` finite and `>= 0`, `max_steps > 0`.
    pub fn new(opts: Dopri5Options) -> Result<Self, SolveError> {
        let bad = |what: &str| {
            Err(SolveError::BadSetting(format!(
                "Dopri5 {what} (got {opts:?})"
            )))
        };
        if !(opts.rtol.is_finite() && opts.rtol > 10.0 * f64::EPSILON) {
            return bad("rtol must be finite and > 10·ε");
        }
        if !(opts.atol.is_finite() && opts.atol >= 0.0) {
            return bad("atol must be finite and >= 0");
        }
        if opts.h_max.is_nan() || opts.h_max <= 0.0 {
            return bad("h_max must be > 0");
        }
        if !(opts.h_init.is_finite() && opts.h_init >= 0.0) {
            return bad("h_init must be finite and >= 0");
        }
        if opts.max_steps == 0 {
            return bad("max_steps must be > 0");
        }
        Ok(Self { opts })
    }

    pub fn options(&self) -> &Dopri5Options {
        &self.opts
    }

    /// Integrates over `knots`; see [`super::solve`] for the contract.
    pub fn solve<S, O, G>(
        &mut self,
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
        self.solve_logged(sys, x, knots, observer, None)
    }

    /// As [`Dopri5::solve`], appending the end time of every accepted step to `log` (the steps
    /// a [`replay`] retakes).
    pub fn solve_logged<S, O, G>(
        &mut self,
        sys: &mut S,
        x: &mut [f64],
        knots: &[f64],
        observer: O,
        log: Option<&mut Vec<f64>>,
    ) -> Result<Stats, SolveError>
    where
        S: OdeSystem,
        O: FnMut(usize, f64, &[f64], &mut S) -> G,
        G: GoOn,
    {
        // A logged run lands on every knot, as its replay does.
        let soft = self.opts.soft_knots && log.is_none();
        let rule = Adaptive {
            opts: &self.opts,
            // The first step is set by `begin` (Hairer's `hinit` needs f at the start).
            ctl: Controller {
                h: 0.0,
                err_old: 1e-4,
                rejected: false,
            },
            span: ends_of(knots).map_or(0.0, |(t0, t1)| t1 - t0),
            shortened: false,
            log,
        };
        drive(sys, x, knots, observer, rule, soft)
    }
}

thread_local! {
    static ATTEMPTS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// The step attempts (accepted and rejected) every adaptive Dormand-Prince run on the calling
/// thread has made so far, a run that ran out of its budget or was stopped by its observer
/// included: a work meter. A caller reads it before and after a playback it runs on one thread
/// (nothing in a playback hands work to another thread) and takes the difference; replays are
/// not counted.
pub fn attempts_on_this_thread() -> u64 {
    ATTEMPTS.with(|a| a.get())
}

/// Where each step of a Dormand-Prince run ends and whether it is kept: the one difference
/// between an adaptive run ([`Adaptive`]) and a replay of its steps ([`Replayed`]), which share
/// everything else ([`drive`]: the start, the knots, the stages, event location and handling).
trait StepRule {
    /// Called once the start point and `k1` are set (may evaluate the system, counted in
    /// `stats`).
    fn begin<S: OdeSystem>(&mut self, _sys: &mut S, _step: &mut Dopri5Step, _stats: &mut Stats) {}
    /// End of the next attempt from `t`, at most `t_knot`; an error stops the run (the step
    /// budget spent, a step too short to advance).
    fn next_end(&mut self, t: f64, t_knot: f64, stats: &Stats) -> Result<f64, SolveError>;
    /// Whether the attempt just made from `t` to `t1` is kept (a rejection is counted here).
    fn keep(&mut self, step: &Dopri5Step, t: f64, t1: f64, stats: &mut Stats) -> bool;
    /// A kept step was accepted and ended at `t` (earlier than planned when an event ended it).
    fn accepted(&mut self, t: f64);
}

/// The adaptive run: the PI controller proposes the steps and the error norm judges them; every
/// accepted step's end is appended to `log` when there is one.
struct Adaptive<'a> {
    opts: &'a Dopri5Options,
    ctl: Controller,
    /// Length of the whole run (s), the scale of the step-underflow test.
    span: f64,
    /// The attempt was cut to end on a knot.
    shortened: bool,
    log: Option<&'a mut Vec<f64>>,
}

impl StepRule for Adaptive<'_> {
    fn begin<S: OdeSystem>(&mut self, sys: &mut S, step: &mut Dopri5Step, stats: &mut Stats) {
        let o = self.opts;
        self.ctl.h = if o.h_init > 0.0 {
            o.h_init.min(o.h_max)
        } else {
            stats.rhs_evals += 1;
            step.initial_step(sys, o.rtol, o.atol, o.h_max)
        };
    }

    fn next_end(&mut self, t: f64, t_knot: f64, stats: &Stats) -> Result<f64, SolveError> {
        let max_steps = self.opts.max_steps;
        if stats.steps_accepted + stats.steps_rejected >= max_steps {
            return Err(SolveError::TooManySteps { t, max_steps });
        }
        ATTEMPTS.with(|a| a.set(a.get() + 1));
        let h = self.ctl.h;
        if h <= 10.0 * f64::EPSILON * t.abs().max(self.span) {
            return Err(SolveError::StepUnderflow { t, h });
        }
        let t1;
        (t1, self.shortened) = if t + 1.01 * h >= t_knot {
            (t_knot, t_knot - t < h)
        } else {
            (t + h, false)
        };
        Ok(t1)
    }

    fn keep(&mut self, step: &Dopri5Step, t: f64, t1: f64, stats: &mut Stats) -> bool {
        let (o, shortened) = (self.opts, self.shortened);
        let err = step.error_norm(o.rtol, o.atol);
        let kept = self.ctl.update(err, t1 - t, shortened, o.h_max);
        if !kept {
            stats.steps_rejected += 1;
        }
        kept
    }

    fn accepted(&mut self, t: f64) {
        if let Some(log) = self.log.as_deref_mut() {
            log.push(t);
        }
    }
}

/// A replay: every step ends at the next logged end or knot, whichever comes first, and is kept.
struct Replayed<'a> {
    /// The logged step ends, sorted.
    ends: &'a [f64],
    /// Index of the first end not yet passed.
    next: usize,
    /// Two step ends closer than this count as one (an event that moved by less).
    tiny: f64,
    max_steps: usize,
}

impl StepRule for Replayed<'_> {
    fn next_end(&mut self, t: f64, t_knot: f64, stats: &Stats) -> Result<f64, SolveError> {
        let max_steps = self.max_steps;
        if stats.steps_accepted >= max_steps {
            return Err(SolveError::TooManySteps { t, max_steps });
        }
        let (ends, tiny) = (self.ends, self.tiny);
        while self.next < ends.len() && ends[self.next] <= t + tiny {
            self.next += 1;
        }
        Ok(match ends.get(self.next) {
            Some(&e) if e < t_knot - tiny => e,
            _ => t_knot,
        })
    }

    fn keep(&mut self, _: &Dopri5Step, _: f64, _: f64, _: &mut Stats) -> bool {
        true
    }

    fn accepted(&mut self, _: f64) {}
}

/// The Dormand-Prince run over `knots` with the steps `rule` chooses (see [`super::solve`] for
/// the contract); with `soft`, the steps pass the soft knots and observe them on their dense
/// output ([`Dopri5Options::soft_knots`]).
fn drive<S, O, R, G>(
    sys: &mut S,
    x: &mut [f64],
    knots: &[f64],
    mut observer: O,
    mut rule: R,
    soft: bool,
) -> Result<Stats, SolveError>
where
    S: OdeSystem,
    O: FnMut(usize, f64, &[f64], &mut S) -> G,
    G: GoOn,
    R: StepRule,
{
    begin(sys, x, knots)?;
    let mut t = knots[0];
    if !observer(0, t, x, sys).go_on() {
        return Err(SolveError::Stopped { t });
    }
    let mut stats = Stats::default();
    if knots.len() == 1 {
        return Ok(stats);
    }
    let mut step = Dopri5Step::new(x.len());
    let mut events = Events::new(sys);
    step.start(sys, t, x);
    events.restart(sys, t, x);
    stats.rhs_evals += 1;
    rule.begin(sys, &mut step, &mut stats);
    let mut passed = Passed::new(x.len());
    let mut next = 1;
    while next < knots.len() {
        // The steps end on the next knot the right-hand side is not smooth across; the soft
        // knots before it are observed on the steps' dense output as the steps pass them.
        let mut hard = next;
        while soft && hard + 1 < knots.len() && sys.soft_knot(hard) {
            hard += 1;
        }
        let t_hard = knots[hard];
        passed.upto = hard;
        passed.next = next;
        while t < t_hard {
            let t1 = rule.next_end(t, t_hard, &stats)?;
            step.attempt(sys, t1);
            stats.rhs_evals += 6;
            if !rule.keep(&step, t, t1, &mut stats) {
                continue;
            }
            t = accept(
                sys,
                &mut step,
                &mut events,
                &mut stats,
                t1,
                x,
                (knots, &mut passed),
            )?;
            rule.accepted(t);
            for j in 0..passed.ks.len() {
                let k = passed.ks[j];
                let n = x.len();
                if !observer(k, knots[k], &passed.xs[j * n..(j + 1) * n], sys).go_on() {
                    return Err(SolveError::Stopped { t: knots[k] });
                }
            }
        }
        if !observer(hard, t_hard, x, sys).go_on() {
            return Err(SolveError::Stopped { t: t_hard });
        }
        next = hard + 1;
    }
    Ok(stats)
}

/// The soft knots a step passed ([`OdeSystem::soft_knot`]), with their states from the step's
/// dense output, for the observer: knots `next..upto` are still to pass.
struct Passed {
    next: usize,
    upto: usize,
    ks: Vec<usize>,
    xs: Vec<f64>,
    buf: Vec<f64>,
}

impl Passed {
    fn new(n: usize) -> Self {
        Self {
            next: 0,
            upto: 0,
            ks: vec![],
            xs: vec![],
            buf: vec![0.0; n],
        }
    }

    /// Takes the knots up to `t_end` (inclusive) from the step just made, before it advances.
    fn take(&mut self, knots: &[f64], step: &Dopri5Step, t_end: f64) {
        self.ks.clear();
        self.xs.clear();
        let (t0, h) = (step.t(), step.h());
        while self.next < self.upto && knots[self.next] <= t_end {
            let k = self.next;
            step.dense(((knots[k] - t0) / h).clamp(0.0, 1.0), &mut self.buf);
            self.ks.push(k);
            self.xs.extend_from_slice(&self.buf);
            self.next += 1;
        }
    }
}

/// Accepts the step just attempted from `step.t()` to `t1`: an event crossing inside it ends
/// the step early at the located time (the step re-taken there, accepted without error
/// control), and the event is handled once the re-taken step confirms it; `x` becomes the
/// step's end. Returns the time reached.
fn accept<S: OdeSystem>(
    sys: &mut S,
    step: &mut Dopri5Step,
    events: &mut Events,
    stats: &mut Stats,
    t1: f64,
    x: &mut [f64],
    (knots, passed): (&[f64], &mut Passed),
) -> Result<f64, SolveError> {
    let t = step.t();
    check_finite(t1, step.x_end())?;
    // An event ends the step early at `t_end`; `fire` once confirmed.
    let (mut t_end, mut fire) = (t1, false);
    if events.crossed(sys, t1, step.x_end()) {
        let h = t1 - t;
        let located = events.locate(sys, t, t1, |s, out| step.dense((s - t) / h, out));
        if let Some(te) = located {
            (t_end, fire) = (te, true);
            if te < t1 {
                step.attempt(sys, te);
                stats.rhs_evals += 6;
                check_finite(te, step.x_end())?;
                // Dense output and the re-taken step may disagree slightly; if the latter has
                // not crossed yet, the next step will.
                fire = events.crossed(sys, te, step.x_end());
            }
        }
    }
    stats.steps_accepted += 1;
    passed.take(knots, step, t_end);
    step.advance();
    x.copy_from_slice(step.x_start());
    if fire {
        sys.handle_event(t_end, x);
        check_finite(t_end, x)?;
        stats.events += 1;
        events.record(t_end)?;
        step.start(sys, t_end, x); // f may jump at an event: no FSAL
        stats.rhs_evals += 1;
        events.restart(sys, t_end, x);
    } else {
        events.step_accepted();
    }
    Ok(t_end)
}

/// Retakes the Dormand-Prince steps of an earlier run: every step ends at the next of `ends` (the
/// step ends [`Dopri5::solve_logged`] recorded, sorted) or at the next knot, whichever comes
/// first, and is accepted without error control; events are located and handled as in
/// [`Dopri5::solve`] (a crossing moved by other parameters splits its step where it now falls).
/// See [`super::solve`] for the contract.
///
/// Why: the result is then a smooth function of the system's parameters (the step sequence does
/// not change with them), so a difference quotient between two replays on the same steps is the
/// derivative of the discretised playback, free of the step-size noise of two adaptive runs
/// ("internal numerical differentiation", Bock 1981).
pub fn replay<S, O, G>(
    sys: &mut S,
    x: &mut [f64],
    knots: &[f64],
    ends: &[f64],
    observer: O,
) -> Result<Stats, SolveError>
where
    S: OdeSystem,
    O: FnMut(usize, f64, &[f64], &mut S) -> G,
    G: GoOn,
{
    let span = ends_of(knots).map_or(0.0, |(t0, t1)| (t1 - t0).abs().max(t0.abs()));
    let rule = Replayed {
        ends,
        next: 0,
        tiny: 1e3 * f64::EPSILON * span.max(1.0),
        max_steps: 2 * ends.len() + 2 * knots.len() + 1000,
    };
    drive(sys, x, knots, observer, rule, false)
}

/// The first and last knot (`None` without knots: [`drive`] refuses them before any step).
fn ends_of(knots: &[f64]) -> Option<(f64, f64)> {
    Some((*knots.first()?, *knots.last()?))
}

/// PI step-size controller state.
struct Controller {
    /// Suggested next step (s).
    h: f64,
    /// Error of the last accepted full-length step (at least 1e-4).
    err_old: f64,
    /// Whether the last attempt was rejected.
    rejected: bool,
}

impl Controller {
    /// Digests the error `err` of an attempted step of length `h`; `true` if it is accepted.
    /// `shortened`: the step was cut to end on a knot (shorter than the suggestion `self.h`).
    fn update(&mut self, err: f64, h: f64, shortened: bool, h_max: f64) -> bool {
        let fac11 = err.powf(0.2 - 0.75 * BETA);
        if err <= 1.0 {
            let fac =
                (fac11 / self.err_old.powf(BETA) / SAFETY).clamp(1.0 / FAC_MAX, 1.0 / FAC_MIN);
            let mut h_new = (h / fac).min(h_max);
            if self.rejected {
                h_new = h_new.min(h);
            }
            if shortened {
                h_new = h_new.max(self.h);
            } else {
                self.err_old = err.max(1e-4);
            }
            self.h = h_new;
            self.rejected = false;
            true
        } else {
            // A NaN error also lands here: `min` then picks 1/FAC_MIN.
            self.h = h / (fac11 / SAFETY).min(1.0 / FAC_MIN);
            self.rejected = true;
            false
        }
    }
}

/// Work vectors and the data of one Dormand-Prince step: start point `(t, x0)` with `k1 = f(t,
/// x0)`, and after [`Dopri5Step::attempt`] the end point `x1` and stages `k2..k7` (`k7 = f(t + h,
/// x1)`). Allocated once; no step method allocates.
#[derive(Debug, Clone)]
pub struct Dopri5Step {
    t: f64,
    t1: f64,
    h: f64,
    x0: Vec<f64>,
    x1: Vec<f64>,
    k: [Vec<f64>; 7],
    stage: Vec<f64>,
}

impl Dopri5Step {
    pub fn new(dim: usize) -> Self {
        Self {
            t: 0.0,
            t1: 0.0,
            h: 0.0,
            x0: vec![0.0; dim],
            x1: vec![0.0; dim],
            k: std::array::from_fn(|_| vec![0.0; dim]),
            stage: vec![0.0; dim],
        }
    }

    /// Sets the start point `(t, x)` and evaluates `k1 = f(t, x)` (one evaluation).
    pub fn start<S: OdeSystem>(&mut self, sys: &mut S, t: f64, x: &[f64]) {
        self.t = t;
        self.x0.copy_from_slice(x);
        sys.rhs(t, &self.x0, &mut self.k[0]);
    }

    /// Takes one step from the start point to `t1` (six evaluations, `k1` is reused). Can be
    /// repeated with another `t1` (rejection, event) until [`Dopri5Step::advance`].
    pub fn attempt<S: OdeSystem>(&mut self, sys: &mut S, t1: f64) {
        let (t, h) = (self.t, t1 - self.t);
        (self.t1, self.h) = (t1, h);
        for s in 1..7 {
            let (done, rest) = self.k.split_at_mut(s);
            let y = if s == 6 {
                &mut self.x1
            } else {
                &mut self.stage
            };
            // y = x0 + h Σ_j A[s][j] k_j, as one vectorisable axpy per earlier stage.
            y.copy_from_slice(&self.x0);
            for (kj, a) in done.iter().zip(&A[s]) {
                if *a != 0.0 {
                    let ha = h * a;
                    for (yi, ki) in y.iter_mut().zip(kj.iter()) {
                        *yi += ha * ki;
                    }
                }
            }
            let ts = if s == 6 { t1 } else { t + C[s] * h };
            sys.rhs(ts, y, &mut rest[0]);
        }
    }

    /// Hairer's RMS error norm of the last attempt (see the module documentation).
    pub fn error_norm(&self, rtol: f64, atol: f64) -> f64 {
        let n = self.x0.len();
        let k: [&[f64]; 7] = std::array::from_fn(|j| &self.k[j][..n]);
        let (x0, x1) = (&self.x0[..n], &self.x1[..n]);
        let mut sum = 0.0;
        for i in 0..n {
            let e = self.h
                * (E[0] * k[0][i]
                    + E[1] * k[1][i]
                    + E[2] * k[2][i]
                    + E[3] * k[3][i]
                    + E[4] * k[4][i]
                    + E[5] * k[5][i]
                    + E[6] * k[6][i]);
            let scale = atol + rtol * x0[i].abs().max(x1[i].abs());
            sum += (e / scale.max(f64::MIN_POSITIVE)).powi(2);
        }
        (sum / n.max(1) as f64).sqrt()
    }

    /// Dense output (fourth-order continuous extension) of the last attempt at
    /// `t + θ·h`, `θ ∈ [0, 1]`, written to `out`. Valid until [`Dopri5Step::advance`].
    pub fn dense(&self, theta: f64, out: &mut [f64]) {
        let (h, th1) = (self.h, 1.0 - theta);
        let (k1, k7) = (&self.k[0], &self.k[6]);
        let n = out.len();
        let k: [&[f64]; 7] = std::array::from_fn(|j| &self.k[j][..n]);
        let (x0, x1) = (&self.x0[..n], &self.x1[..n]);
        for (i, o) in out.iter_mut().enumerate() {
            let dx = x1[i] - x0[i];
            let b = h * k1[i] - dx;
            let d = D[0] * k[0][i]
                + D[1] * k[1][i]
                + D[2] * k[2][i]
                + D[3] * k[3][i]
                + D[4] * k[4][i]
                + D[5] * k[5][i]
                + D[6] * k[6][i];
            let r4 = dx - h * k7[i] - b;
            *o = x0[i] + theta * (dx + th1 * (b + theta * (r4 + th1 * h * d)));
        }
    }

    /// Accepts the last attempt: its end becomes the start point, `k1 ← k7` (FSAL).
    pub fn advance(&mut self) {
        self.t = self.t1;
        std::mem::swap(&mut self.x0, &mut self.x1);
        self.k.swap(0, 6);
    }

    /// Start time of the current step.
    pub fn t(&self) -> f64 {
        self.t
    }
    /// Length of the last attempt.
    pub fn h(&self) -> f64 {
        self.h
    }
    /// State at the start point.
    pub fn x_start(&self) -> &[f64] {
        &self.x0
    }
    /// Fifth-order state at the end of the last attempt.
    pub fn x_end(&self) -> &[f64] {
        &self.x1
    }

    /// Hairer's `hinit`: an initial step from the start point such that an explicit Euler step is
    /// small against the solution and `h⁵·max(‖f‖, ‖f'‖) ≈ 0.01` (norms weighted as the error
    /// norm with `|x0|`); at most `h_max`. One evaluation; clobbers `x1` and `k2`.
    pub fn initial_step<S: OdeSystem>(
        &mut self,
        sys: &mut S,
        rtol: f64,
        atol: f64,
        h_max: f64,
    ) -> f64 {
        let n = self.x0.len().max(1) as f64;
        let scale = |x: f64| (atol + rtol * x.abs()).max(f64::MIN_POSITIVE);
        let rms = |f: &dyn Fn(usize) -> f64| {
            ((0..self.x0.len())
                .map(|i| (f(i) / scale(self.x0[i])).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        };
        let d0 = rms(&|i| self.x0[i]);
        let d1 = rms(&|i| self.k[0][i]);
        let h0 = (if d0 <= 1e-5 || d1 <= 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        })
        .min(h_max);
        for i in 0..self.x0.len() {
            self.x1[i] = self.x0[i] + h0 * self.k[0][i];
        }
        let (head, tail) = self.k.split_at_mut(1);
        sys.rhs(self.t + h0, &self.x1, &mut tail[0]);
        let (k1, k2) = (&head[0], &tail[0]);
        let d2 = rms(&|i| k2[i] - k1[i]) / h0;
        let der = d1.max(d2);
        let h1 = if der <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / der).powf(0.2)
        };
        let h = (100.0 * h0).min(h1).min(h_max);
        if h.is_finite() && h > 0.0 {
            h
        } else {
            1e-6_f64.min(h_max)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::rk4::tests::*;
    use super::super::{solve, Method};
    use super::*;

    fn opts(rtol: f64, atol: f64, h_max: f64) -> Dopri5Options {
        Dopri5Options {
            rtol,
            atol,
            h_max,
            ..Dopri5Options::default()
        }
    }

    /// Fixed-step Dormand-Prince over `[0, 2]` in `n` steps; error at `t = 2`.
    fn fixed_step_error(n: usize) -> f64 {
        let mut step = Dopri5Step::new(2);
        step.start(&mut Oscillator, 0.0, &Oscillator::exact(0.0));
        for i in 1..=n {
            step.attempt(&mut Oscillator, 2.0 * i as f64 / n as f64);
            step.advance();
        }
        max_err(step.x_start(), &Oscillator::exact(2.0))
    }

    /// Dense output at `θ` of one step of length `h` from the exact state at `t0 = 0.3`.
    fn dense_error(h: f64, theta: f64) -> f64 {
        let t0 = 0.3;
        let mut step = Dopri5Step::new(2);
        step.start(&mut Oscillator, t0, &Oscillator::exact(t0));
        step.attempt(&mut Oscillator, t0 + h);
        let mut out = [0.0; 2];
        step.dense(theta, &mut out);
        max_err(&out, &Oscillator::exact(t0 + theta * h))
    }

    #[test]
    fn dopri5_fixed_step_order_is_five() {
        let errs: Vec<f64> = [10, 20, 40].iter().map(|&n| fixed_step_error(n)).collect();
        let p = orders(&errs);
        eprintln!("Dopri5 fixed-step errors at t=2 {errs:?}, observed orders {p:.4?}");
        assert!(p.iter().all(|p| (4.7..=5.3).contains(p)), "{p:?}");
    }

    #[test]
    fn dopri5_dense_output_local_order_is_five() {
        let errs: Vec<f64> = [0.2, 0.1, 0.05]
            .iter()
            .map(|&h| dense_error(h, 0.37))
            .collect();
        let p = orders(&errs);
        eprintln!("Dopri5 dense output errors at theta=0.37 {errs:?}, observed orders {p:.4?}");
        assert!(p.iter().all(|p| (4.5..=5.5).contains(p)), "{p:?}");
        // The interpolant passes through both ends of the step.
        let mut step = Dopri5Step::new(2);
        step.start(&mut Oscillator, 0.3, &Oscillator::exact(0.3));
        step.attempt(&mut Oscillator, 0.5);
        let mut out = [0.0; 2];
        step.dense(0.0, &mut out);
        assert!(max_err(&out, step.x_start()) < 1e-15);
        step.dense(1.0, &mut out);
        assert!(max_err(&out, step.x_end()) < 1e-15);
    }

    #[test]
    fn dopri5_error_falls_with_rtol() {
        let errs: Vec<f64> = [1e-3, 1e-5, 1e-7, 1e-9]
            .iter()
            .map(|&rtol| oscillator_error(&Method::Dopri5(opts(rtol, rtol, 1.0)), &[0.0, 2.0]))
            .collect();
        eprintln!("Dopri5 errors at t=2 for rtol = 1e-3, 1e-5, 1e-7, 1e-9: {errs:?}");
        assert!(errs.windows(2).all(|w| w[1] < w[0]), "{errs:?}");
        assert!(errs[3] < 1e-7, "{errs:?}");
    }

    #[test]
    fn dopri5_observer_gets_every_knot() {
        check_observer_knots(&Method::Dopri5(opts(1e-10, 1e-12, 0.1)), 1e-8);
    }

    #[test]
    fn dopri5_knot_grid_matches_single_interval() {
        let fine: Vec<f64> = (0..=20).map(|i| i as f64 * 0.1).collect();
        let (mut a, mut b) = (Oscillator::exact(0.0), Oscillator::exact(0.0));
        let m = Method::Dopri5(opts(1e-10, 1e-12, 1.0));
        solve(&m, &mut Oscillator, &mut a, &[0.0, 2.0], |_, _, _, _| {}).unwrap();
        solve(&m, &mut Oscillator, &mut b, &fine, |_, _, _, _| {}).unwrap();
        let d = max_err(&a, &b);
        eprintln!("Dopri5 single interval vs 0.1-s knots: difference {d:e}");
        assert!(d < 1e-9, "{d:e}");
    }

    #[test]
    fn dopri5_short_knot_intervals_do_not_shrink_the_step() {
        // Intervals alternate 0.1 s and 1 ms. The natural step (~0.3 s at rtol 1e-3) exceeds both,
        // so every interval should take one step; collapsing the suggestion after each 1-ms step
        // would need about three steps per pair.
        let mut knots = vec![0.0];
        for i in 0..40 {
            let last = *knots.last().unwrap();
            knots.push(last + if i % 2 == 0 { 0.1 } else { 1e-3 });
        }
        let mut x = Oscillator::exact(0.0);
        let m = Method::Dopri5(Dopri5Options {
            h_init: 0.1,
            ..opts(1e-3, 1e-3, 1.0)
        });
        let stats = solve(&m, &mut Oscillator, &mut x, &knots, |_, _, _, _| {}).unwrap();
        eprintln!("Dopri5 on 40 short intervals: {stats:?}");
        assert!(
            stats.steps_accepted + stats.steps_rejected <= 40 + 2,
            "{stats:?}"
        );
        assert!(max_err(&x, &Oscillator::exact(*knots.last().unwrap())) < 1e-3);
    }

    #[test]
    fn dopri5_fsal_carries_across_knots() {
        let knots: Vec<f64> = (0..=20).map(|i| i as f64 * 0.1).collect();
        for (h_init, setup_evals) in [(0.05, 1), (0.0, 2)] {
            let o = Dopri5Options {
                h_init,
                ..opts(1e-6, 1e-8, 1.0)
            };
            let mut x = Oscillator::exact(0.0);
            let s = solve(
                &Method::Dopri5(o),
                &mut Oscillator,
                &mut x,
                &knots,
                |_, _, _, _| {},
            )
            .unwrap();
            assert_eq!(
                s.rhs_evals,
                setup_evals + 6 * (s.steps_accepted + s.steps_rejected),
                "{s:?}"
            );
            assert!(s.steps_accepted >= 20);
        }
    }

    /// A logged run's steps, replayed on the same system, give the same trajectory bit for bit
    /// (the same steps from the same states), in as many steps.
    #[test]
    fn a_replay_retakes_a_logged_runs_steps() {
        let knots = [0.3, 0.5, 1.0, 2.0, 4.0];
        let log = super::super::StepLog::default();
        let logged = Method::Dopri5Logged(opts(1e-6, 1e-8, 0.5), log.clone());
        let mut x = Oscillator::exact(0.3);
        let mut seen = vec![];
        let s1 = solve(&logged, &mut Oscillator, &mut x, &knots, |_, _, x, _| {
            seen.push(x.to_vec())
        })
        .unwrap();
        let steps = log.times();
        assert_eq!(steps.len(), s1.steps_accepted);
        assert!(s1.steps_rejected + s1.steps_accepted > 10);
        let mut y = Oscillator::exact(0.3);
        let mut again = vec![];
        let s2 = solve(
            &Method::Replay(steps),
            &mut Oscillator,
            &mut y,
            &knots,
            |_, _, x, _| again.push(x.to_vec()),
        )
        .unwrap();
        assert_eq!(s2.steps_accepted, s1.steps_accepted);
        assert_eq!(s2.steps_rejected, 0);
        assert_eq!(seen, again);
    }

    /// `x' = a·cos t` with a non-windup upper limit 0.5 that holds until the input turns
    /// negative at π/2: `x` reaches the limit at `asin(0.5/a)` and ends at `x(3) = 0.5 +
    /// a·(sin 3 − 1)`, so `dx(3)/da = sin 3 − 1` although the switch moves with `a`.
    struct ScaledLimiter {
        a: f64,
        held: bool,
        hit: Option<f64>,
    }

    impl OdeSystem for ScaledLimiter {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = if self.held { 0.0 } else { self.a * t.cos() };
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = if self.held { t.cos() } else { 0.5 - x[0] };
        }
        fn handle_event(&mut self, t: f64, x: &mut [f64]) -> bool {
            let switch = if self.held {
                t.cos() <= 1e-9
            } else {
                0.5 - x[0] <= 1e-9
            };
            if switch {
                self.held = !self.held;
                if self.held {
                    x[0] = 0.5;
                    self.hit = Some(t);
                }
            }
            switch
        }
    }

    fn limited_end(a: f64, method: &Method) -> (f64, f64) {
        let mut sys = ScaledLimiter {
            a,
            held: false,
            hit: None,
        };
        let mut x = [0.0];
        solve(
            method,
            &mut sys,
            &mut x,
            &[0.0, 1.0, 2.0, 3.0],
            |_, _, _, _| {},
        )
        .unwrap();
        (x[0], sys.hit.unwrap())
    }

    /// Replays of the steps of one run at a coarse tolerance, at parameters `a` and `a + h`,
    /// differ by the derivative of the discretised solution: here within 1e-6 of the exact
    /// `dx(3)/da` at `h = 1e-7`, with the limiter's switch located anew in each replay (its time
    /// moves by 4e-8 s), and the replays' switch times are the exact ones.
    #[test]
    fn replays_differentiate_through_a_moving_switch() {
        let log = super::super::StepLog::default();
        let a = 1.2;
        limited_end(a, &Method::Dopri5Logged(opts(1e-6, 1e-8, 0.3), log.clone()));
        let replay = Method::Replay(log.times());
        let h = 1e-7;
        let (x0, t0) = limited_end(a, &replay);
        let (x1, t1) = limited_end(a + h, &replay);
        for (aa, t) in [(a, t0), (a + h, t1)] {
            assert!((t - (0.5 / aa).asin()).abs() < 1e-9, "switch at {t}");
        }
        assert!(t1 < t0);
        let d = (x1 - x0) / h;
        let exact = 3f64.sin() - 1.0;
        assert!((d - exact).abs() < 1e-6 * exact.abs(), "{d} for {exact}");
    }

    #[test]
    fn dopri5_initial_step_is_sane() {
        let mut step = Dopri5Step::new(2);
        // At t = 0 the slope is zero: Hairer's fallback h0 = 1e-6, result 100·h0.
        step.start(&mut Oscillator, 0.0, &Oscillator::exact(0.0));
        let h = step.initial_step(&mut Oscillator, 1e-6, 1e-8, 1.0);
        assert!((h - 1e-4).abs() < 1e-12, "h = {h}");
        // At t = 0.3: h0 = 0.01·‖x‖/‖f‖ ≈ 0.01, ‖f'‖ ≈ 1e6 (weights ~1e-6): h ≈ (1e-8)^(1/5).
        let t0 = 0.3;
        step.start(&mut Oscillator, t0, &Oscillator::exact(t0));
        let h = step.initial_step(&mut Oscillator, 1e-6, 1e-8, 1.0);
        assert!((0.01..=0.1).contains(&h), "h = {h}");
        assert_eq!(step.initial_step(&mut Oscillator, 1e-6, 1e-8, 1e-3), 1e-3);
        // It is accepted as a first step.
        step.start(&mut Oscillator, t0, &Oscillator::exact(t0));
        step.attempt(&mut Oscillator, t0 + h);
        assert!(step.error_norm(1e-6, 1e-8) <= 1.0);
    }

    #[test]
    fn dopri5_limiter_event_located_with_coarse_step() {
        check_limiter_pins(&Method::Dopri5(opts(1e-6, 1e-8, 0.3)));
    }

    #[test]
    fn dopri5_limiter_holds_and_releases() {
        let (e1, e2, ex) = limiter_release_errors(&Method::Dopri5(opts(1e-10, 1e-12, 0.1)));
        eprintln!("Dopri5 release: event errors {e1:.2e}, {e2:.2e}; x(3) error {ex:.2e}");
        assert!(e1 < 1e-8 && e2 < 1e-10 && ex < 1e-8, "{e1:e} {e2:e} {ex:e}");
        let (_, e2, _) = limiter_release_errors(&Method::Dopri5(opts(1e-4, 1e-6, 0.3)));
        assert!(e2 < 1e-10, "{e2:e}");
    }

    #[test]
    fn dopri5_event_retakes_step_to_event_time() {
        check_turn_retakes_step(&Method::Dopri5(opts(1e-6, 1e-8, 0.3)));
    }

    #[test]
    fn dopri5_earliest_of_two_crossings_first() {
        let o = Dopri5Options {
            h_init: 0.3,
            ..opts(1e-6, 1e-8, 0.3)
        };
        check_earliest_guard_first(&Method::Dopri5(o));
    }

    #[test]
    fn dopri5_controller() {
        let mut c = Controller {
            h: 0.1,
            err_old: 1e-4,
            rejected: false,
        };
        // Rejection: shrink, at most by FAC_MIN.
        assert!(!c.update(2.0, 0.1, false, 1.0));
        assert!(c.h < 0.1 && c.h >= 0.1 * FAC_MIN, "{}", c.h);
        // A tiny error right after a rejection: accepted, but no growth.
        let h = c.h;
        assert!(c.update(1e-12, h, false, 1.0));
        assert_eq!(c.h, h);
        // Then growth, at most by FAC_MAX, and capped by h_max.
        assert!(c.update(1e-12, h, false, 1.0));
        assert!((c.h - FAC_MAX * h).abs() < 1e-15, "{}", c.h);
        assert!(c.update(1e-12, c.h, false, 0.05));
        assert_eq!(c.h, 0.05);
        // A step cut short at a knot keeps the earlier suggestion and error history.
        let (h, err_old) = (c.h, c.err_old);
        assert!(c.update(1e-3, 1e-4, true, 1.0));
        assert_eq!((c.h, c.err_old), (h, err_old));
        // Larger error on a full step: smaller suggestion; err = 1 still accepted.
        assert!(c.update(1.0, h, false, 1.0));
        assert!(c.h < h);
        // A non-finite error is a rejection by FAC_MIN.
        assert!(!c.update(f64::NAN, 0.01, false, 1.0));
        assert!((c.h - 0.01 * FAC_MIN).abs() < 1e-15);
    }

    #[test]
    fn dopri5_chattering_modes_are_an_error() {
        check_chatter_is_error(&Method::Dopri5(Dopri5Options::default()));
    }

    #[test]
    fn dopri5_retrigger_within_deadband_is_ignored() {
        check_retrigger_ignored(&Method::Dopri5(opts(1e-6, 1e-8, 0.3)));
    }

    #[test]
    fn dopri5_errors() {
        check_failures(&Method::Dopri5(Dopri5Options::default()));

        let o = Dopri5Options {
            max_steps: 5,
            ..Dopri5Options::default()
        };
        let r = solve(
            &Method::Dopri5(o),
            &mut Oscillator,
            &mut [1.0, 0.0],
            &[0.0, 2.0],
            |_, _, _, _| {},
        );
        assert!(
            matches!(r, Err(SolveError::TooManySteps { max_steps: 5, .. })),
            "{r:?}"
        );

        let d = Dopri5Options::default;
        assert!(Dopri5::new(d()).is_ok());
        assert!(Dopri5::new(Dopri5Options {
            h_max: f64::INFINITY,
            atol: 0.0,
            ..d()
        })
        .is_ok());
        for bad in [
            Dopri5Options { rtol: 0.0, ..d() },
            Dopri5Options { rtol: -1e-6, ..d() },
            Dopri5Options { rtol: 1e-17, ..d() },
            Dopri5Options {
                rtol: f64::NAN,
                ..d()
            },
            Dopri5Options { atol: -1.0, ..d() },
            Dopri5Options {
                atol: f64::INFINITY,
                ..d()
            },
            Dopri5Options { h_max: 0.0, ..d() },
            Dopri5Options {
                h_max: f64::NAN,
                ..d()
            },
            Dopri5Options {
                h_init: -0.1,
                ..d()
            },
            Dopri5Options {
                h_init: f64::NAN,
                ..d()
            },
            Dopri5Options {
                max_steps: 0,
                ..d()
            },
        ] {
            assert!(
                matches!(Dopri5::new(bad.clone()), Err(SolveError::BadSetting(_))),
                "{bad:?}"
            );
        }
    }
}
