//! Classical fourth-order Runge-Kutta at a fixed step.
//!
//! Tableau: the classical method of Kutta (1901) as given in Hairer, Nørsett & Wanner,
//! *Solving ODEs I*, §II.1, Table 1.2 (left):
//!
//! ```text
//! k1 = f(t,       x)
//! k2 = f(t + h/2, x + h/2·k1)
//! k3 = f(t + h/2, x + h/2·k2)
//! k4 = f(t + h,   x + h·k3)
//! x(t + h) ≈ x + h/6·(k1 + 2·k2 + 2·k3 + k4)
//! ```
//!
//! Each knot interval `Δ` is split into `ceil(Δ/h - 1e-9)` equal sub-steps (the `1e-9` keeps an
//! interval that is a multiple of `h` up to rounding from getting one extra sliver step), so steps
//! land exactly on the knots. Events are located on the cubic Hermite interpolant built from
//! `(x0, f0, x1, f1)` of the step (one extra right-hand-side evaluation, only when a sign change
//! is seen); the step is then re-taken as a shorter RK4 step that ends at the event.
//!
//! **Step budget.** Twice the grid's steps plus 100: an event may cut every step short once;
//! modes switching several times within most steps fail with [`SolveError::TooManySteps`].
//!
//! **Stability check.** Before the first step the driver linearises the system at the start (a
//! forward-difference Jacobian of the right-hand side, `n + 1` evaluations) and refuses, with
//! [`SolveError::Stiff`], a step at which a mode `λ` has `h·|λ|` beyond
//! [`RK4_STABLE_HLAMBDA`]: there RK4 amplifies the mode at every step, and where a limit holds
//! the state it does not even blow up, it gives a finite wrong trajectory. The check sees the
//! modes of the start only: a mode that becomes fast later (a limit releasing a state, a
//! saturation curve steepening) is not seen, and the step budget is then the only guard. Use
//! Dormand-Prince (the default) where a run leaves the start's operating point far behind.

use super::{begin, check_finite, Events, GoOn, OdeSystem, SolveError, Stats};

/// Largest `h·|λ|` at which [`Rk4`] integrates a mode `λ` of the start's linearisation. RK4's
/// region of absolute stability reaches -2.785 on the negative real axis and ±2.828 on the
/// imaginary axis, and holds the half-disc `|z| <= 2.5` of the left half-plane; 2.5 keeps every
/// decaying mode, real or oscillatory, inside it.
pub const RK4_STABLE_HLAMBDA: f64 = 2.5;

/// Fixed-step classical RK4 driver (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Rk4 {
    h: f64,
}

impl Rk4 {
    /// Largest step `h` in seconds; must be finite and positive.
    pub fn new(h: f64) -> Result<Self, SolveError> {
        if h.is_finite() && h > 0.0 {
            Ok(Self { h })
        } else {
            Err(SolveError::BadSetting(format!(
                "RK4 step must be finite and > 0 (got {h})"
            )))
        }
    }

    /// Largest step in seconds.
    pub fn h(&self) -> f64 {
        self.h
    }

    /// Integrates over `knots`; see [`super::solve`] for the contract.
    pub fn solve<S, O, G>(
        &mut self,
        sys: &mut S,
        x: &mut [f64],
        knots: &[f64],
        mut observer: O,
    ) -> Result<Stats, SolveError>
    where
        S: OdeSystem,
        O: FnMut(usize, f64, &[f64], &mut S) -> G,
        G: GoOn,
    {
        begin(sys, x, knots)?;
        let mut t = knots[0];
        // The longest step taken: `h`, or the longest knot interval when every one is shorter.
        let h_taken = knots
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(0.0, f64::max)
            .min(self.h);
        // The step budget: every grid step once more (an event may cut each short once), plus
        // 100. Modes that switch several times within most steps (a limiter chattering on a
        // candidate whose loop is unstable at the limit) have no meaningful RK4 solution, and
        // locating each switch would cost without bound.
        let max_steps = 2 * knots
            .windows(2)
            .map(|w| sub_steps(w[1] - w[0], self.h))
            .sum::<usize>()
            + 100;
        let rate = fastest_rate(sys, t, x);
        if h_taken * rate > RK4_STABLE_HLAMBDA {
            return Err(SolveError::Stiff { h: h_taken, rate });
        }
        if !observer(0, t, x, sys).go_on() {
            return Err(SolveError::Stopped { t });
        }

        let n = x.len();
        let mut stats = Stats::default();
        let mut work = Rk4Work::new(n);
        let mut x_new = vec![0.0; n];
        let mut f_new = vec![0.0; if sys.n_events() > 0 { n } else { 0 }];
        let mut events = Events::new(sys);
        events.restart(sys, t, x);

        for (k, w) in knots.windows(2).enumerate() {
            let (ta, tb) = (w[0], w[1]);
            let m = sub_steps(tb - ta, self.h);
            let dt = (tb - ta) / m as f64;
            for i in 1..=m {
                let t_grid = if i == m { tb } else { ta + i as f64 * dt };
                // More than one pass only when an event cuts the step short.
                while t < t_grid {
                    let h = t_grid - t;
                    rk4_step(sys, t, x, h, &mut x_new, &mut work);
                    stats.rhs_evals += 4;
                    check_finite(t_grid, &x_new)?;

                    // An event ends the step early at `t_end`; `fire` once confirmed.
                    let (mut t_end, mut fire) = (t_grid, false);
                    if events.crossed(sys, t_grid, &x_new) {
                        sys.rhs(t_grid, &x_new, &mut f_new);
                        stats.rhs_evals += 1;
                        let (x0, f0, x1, f1) = (&*x, &work.k1, &x_new, &f_new);
                        let located = events.locate(sys, t, t_grid, |s, out| {
                            hermite((s - t) / h, h, x0, f0, x1, f1, out)
                        });
                        if let Some(te) = located {
                            (t_end, fire) = (te, true);
                            if te < t_grid {
                                rk4_step(sys, t, x, te - t, &mut x_new, &mut work);
                                stats.rhs_evals += 4;
                                check_finite(te, &x_new)?;
                                // The interpolant may disagree slightly with the re-taken step;
                                // if that has not crossed yet, the next step will.
                                fire = events.crossed(sys, te, &x_new);
                            }
                        }
                    }

                    stats.steps_accepted += 1;
                    if stats.steps_accepted > max_steps {
                        return Err(SolveError::TooManySteps { t, max_steps });
                    }
                    x.copy_from_slice(&x_new);
                    t = t_end;
                    if fire {
                        sys.handle_event(t, x);
                        check_finite(t, x)?;
                        stats.events += 1;
                        events.record(t)?;
                        events.restart(sys, t, x);
                    } else {
                        events.step_accepted();
                    }
                }
            }
            if !observer(k + 1, tb, x, sys).go_on() {
                return Err(SolveError::Stopped { t: tb });
            }
        }
        Ok(stats)
    }
}

/// The largest `|λ|` among the eigenvalues of the Jacobian of `sys` at `(t, x)` (forward
/// differences with steps `1e-7·max(1, |x_i|)`); 0 for a system without states, and `+∞` when the
/// right-hand side is not finite around `x`. Leaves the system as evaluated at `(t, x)`.
pub fn fastest_rate<S: OdeSystem>(sys: &mut S, t: f64, x: &[f64]) -> f64 {
    let n = x.len();
    if n == 0 {
        return 0.0;
    }
    let mut f0 = vec![0.0; n];
    sys.rhs(t, x, &mut f0);
    let (mut xp, mut fp) = (x.to_vec(), vec![0.0; n]);
    let mut jac = nalgebra::DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        let d = 1e-7 * x[j].abs().max(1.0);
        xp[j] = x[j] + d;
        sys.rhs(t, &xp, &mut fp);
        xp[j] = x[j];
        for i in 0..n {
            jac[(i, j)] = (fp[i] - f0[i]) / d;
        }
    }
    // The system's caches (signals, outputs) are left as at `x`, as an observer may read them.
    sys.rhs(t, x, &mut f0);
    if jac.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    jac.complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max)
}

/// Number of equal sub-steps for an interval `delta` with largest step `h`.
fn sub_steps(delta: f64, h: f64) -> usize {
    (delta / h - 1e-9).ceil().max(1.0) as usize
}

/// Work vectors of one RK4 step (allocated once, reused by every step).
#[derive(Debug, Clone)]
pub struct Rk4Work {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    stage: Vec<f64>,
}

impl Rk4Work {
    pub fn new(dim: usize) -> Self {
        let v = vec![0.0; dim];
        Self {
            k1: v.clone(),
            k2: v.clone(),
            k3: v.clone(),
            k4: v.clone(),
            stage: v,
        }
    }

    /// `f(t, x)` at the start of the last step.
    pub fn k1(&self) -> &[f64] {
        &self.k1
    }
}

/// One classical RK4 step of length `h` from `(t, x)`; writes `x(t + h)` to `out`.
/// Four right-hand-side evaluations; `work` must be sized for `sys.dim()`.
pub fn rk4_step<S: OdeSystem>(
    sys: &mut S,
    t: f64,
    x: &[f64],
    h: f64,
    out: &mut [f64],
    work: &mut Rk4Work,
) {
    let Rk4Work {
        k1,
        k2,
        k3,
        k4,
        stage,
    } = work;
    let half = 0.5 * h;
    sys.rhs(t, x, k1);
    axpy(stage, x, half, k1);
    sys.rhs(t + half, stage, k2);
    axpy(stage, x, half, k2);
    sys.rhs(t + half, stage, k3);
    axpy(stage, x, h, k3);
    sys.rhs(t + h, stage, k4);
    let h6 = h / 6.0;
    for i in 0..x.len() {
        out[i] = x[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
}

/// `out = x + a·k`.
fn axpy(out: &mut [f64], x: &[f64], a: f64, k: &[f64]) {
    for ((o, &xi), &ki) in out.iter_mut().zip(x).zip(k) {
        *o = xi + a * ki;
    }
}

/// Cubic Hermite interpolant on a step of length `h` at `theta ∈ [0, 1]` from the end values
/// `x0, x1` and slopes `f0, f1`.
fn hermite(theta: f64, h: f64, x0: &[f64], f0: &[f64], x1: &[f64], f1: &[f64], out: &mut [f64]) {
    let s = theta;
    let r = 1.0 - s;
    let (h00, h01) = ((1.0 + 2.0 * s) * r * r, s * s * (3.0 - 2.0 * s));
    let (h10, h11) = (h * s * r * r, -h * s * s * r);
    for i in 0..out.len() {
        out[i] = h00 * x0[i] + h01 * x1[i] + h10 * f0[i] + h11 * f1[i];
    }
}

#[cfg(test)]
pub(super) mod tests {
    //! Test systems shared with the Dopri5 tests, and the RK4 tests.
    use super::super::{solve, Method};
    use super::*;

    /// Forced undamped oscillator `x1' = x2`, `x2' = -x1 + cos 2t`, `x(0) = (1, 0)`:
    /// `x1 = (4/3)·cos t - (1/3)·cos 2t`, `x2 = x1'`.
    pub struct Oscillator;

    impl Oscillator {
        pub fn exact(t: f64) -> [f64; 2] {
            let (s1, c1) = t.sin_cos();
            let (s2, c2) = (2.0 * t).sin_cos();
            [(4.0 * c1 - c2) / 3.0, (2.0 * s2 - 4.0 * s1) / 3.0]
        }
    }

    impl OdeSystem for Oscillator {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -x[0] + (2.0 * t).cos();
        }
    }

    pub fn max_err(x: &[f64], exact: &[f64]) -> f64 {
        x.iter()
            .zip(exact)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }

    /// `log2` of successive error ratios (observed orders for halved steps).
    pub fn orders(errs: &[f64]) -> Vec<f64> {
        errs.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
    }

    /// Error at `t = 2` of a run over `knots` starting from the exact initial state.
    pub fn oscillator_error(method: &Method, knots: &[f64]) -> f64 {
        let mut x = Oscillator::exact(knots[0]);
        solve(method, &mut Oscillator, &mut x, knots, |_, _, _, _| {}).unwrap();
        max_err(&x, &Oscillator::exact(*knots.last().unwrap()))
    }

    /// Integrator `x' = rate(t)` with a non-windup upper limit `LIMIT`. Free: event
    /// `LIMIT - x`; the event pins `x` and holds (`x' = 0`). Held: event `rate(t)` if `release`
    /// (leave when the input stops pushing up), else `1` (never). Records event times.
    pub struct Limiter {
        pub rate: fn(f64) -> f64,
        pub release: bool,
        pub held: bool,
        pub event_times: Vec<f64>,
    }

    pub const LIMIT: f64 = 0.5;

    impl Limiter {
        pub fn new(rate: fn(f64) -> f64, release: bool) -> Self {
            Self {
                rate,
                release,
                held: false,
                event_times: Vec::new(),
            }
        }
    }

    impl OdeSystem for Limiter {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = if self.held { 0.0 } else { (self.rate)(t) };
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = match (self.held, self.release) {
                (false, _) => LIMIT - x[0],
                (true, true) => (self.rate)(t),
                (true, false) => 1.0,
            };
        }
        fn handle_event(&mut self, t: f64, x: &mut [f64]) -> bool {
            let switch = if self.held {
                self.release && (self.rate)(t) <= 1e-9
            } else {
                LIMIT - x[0] <= 1e-9
            };
            if switch {
                self.held = !self.held;
                if self.held {
                    x[0] = LIMIT;
                }
                self.event_times.push(t);
            }
            switch
        }
    }

    /// `x' = 1` up to the limit; `x' = 1` through it from a tight knot grid observed, with
    /// `x` staying exactly at the limit afterwards.
    pub fn check_limiter_pins(method: &Method) {
        let mut sys = Limiter::new(|_| 1.0, false);
        let knots = [0.0, 0.7, 1.0, 1.55, 2.0];
        let mut x = [0.0];
        let mut seen = Vec::new();
        let stats = solve(method, &mut sys, &mut x, &knots, |_, t, x, _| {
            seen.push((t, x[0]))
        })
        .unwrap();
        assert_eq!(stats.events, 1);
        assert_eq!(sys.event_times.len(), 1);
        let te = sys.event_times[0];
        assert!((te - 0.5).abs() < 1e-10, "event at {te}");
        assert_eq!(seen[0], (0.0, 0.0));
        for &(t, xk) in &seen[1..] {
            assert_eq!(xk, LIMIT, "x at t = {t}");
        }
    }

    /// `x' = cos t`: `x = sin t` hits the limit at π/6, is held until the input turns negative
    /// at π/2, then follows `sin t - 1/2`. Returns the error of the event times and of `x(3)`.
    pub fn limiter_release_errors(method: &Method) -> (f64, f64, f64) {
        let mut sys = Limiter::new(f64::cos, true);
        let mut x = [0.0];
        let stats = solve(
            method,
            &mut sys,
            &mut x,
            &[0.0, 1.0, 2.0, 3.0],
            |_, _, _, _| {},
        )
        .unwrap();
        assert_eq!(stats.events, 2, "{:?}", sys.event_times);
        assert!(!sys.held);
        let pi = std::f64::consts::PI;
        let t = &sys.event_times;
        (
            (t[0] - pi / 6.0).abs(),
            (t[1] - pi / 2.0).abs(),
            (x[0] - (3f64.sin() - 0.5)).abs(),
        )
    }

    /// `x' = ±1`: up until `x` reaches 0.5 (event `0.5 - x`), then down, no projection. The
    /// state after the turn is only right if the step is re-taken to the event time.
    pub struct Turn {
        pub down: bool,
    }

    impl OdeSystem for Turn {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = if self.down { -1.0 } else { 1.0 };
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, _t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = if self.down { 1.0 } else { 0.5 - x[0] };
        }
        fn handle_event(&mut self, _t: f64, x: &mut [f64]) -> bool {
            let turn = !self.down && 0.5 - x[0] <= 1e-9;
            self.down |= turn;
            turn
        }
    }

    pub fn check_turn_retakes_step(method: &Method) {
        let mut x = [0.0];
        let mut seen = Vec::new();
        let stats = solve(
            method,
            &mut Turn { down: false },
            &mut x,
            &[0.0, 0.7, 2.0],
            |_, t, x, _| seen.push((t, x[0])),
        )
        .unwrap();
        assert_eq!(stats.events, 1);
        for (t, xk) in seen {
            let exact = if t <= 0.5 { t } else { 1.0 - t };
            assert!((xk - exact).abs() < 1e-10, "x({t}) = {xk}");
        }
    }

    /// `x' = 1` with two one-shot guards at `x = 0.55` (event 0) and `x = 0.4` (event 1), both
    /// inside one coarse step: the earlier must be handled first. Records `(t, guard)`.
    pub struct TwoGuards {
        pub fired: [bool; 2],
        pub log: Vec<(f64, usize)>,
    }

    const GUARDS: [f64; 2] = [0.55, 0.4];

    impl OdeSystem for TwoGuards {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = 1.0;
        }
        fn n_events(&self) -> usize {
            2
        }
        fn events(&mut self, _t: f64, x: &[f64], g: &mut [f64]) {
            for ((g, fired), guard) in g.iter_mut().zip(self.fired).zip(GUARDS) {
                *g = if fired { 1.0 } else { guard - x[0] };
            }
        }
        fn handle_event(&mut self, t: f64, x: &mut [f64]) -> bool {
            let mut changed = false;
            for (i, (fired, guard)) in self.fired.iter_mut().zip(GUARDS).enumerate() {
                if !*fired && guard - x[0] <= 1e-9 {
                    *fired = true;
                    self.log.push((t, i));
                    changed = true;
                }
            }
            changed
        }
    }

    pub fn check_earliest_guard_first(method: &Method) {
        let mut sys = TwoGuards {
            fired: [false; 2],
            log: Vec::new(),
        };
        let stats = solve(method, &mut sys, &mut [0.0], &[0.0, 0.9], |_, _, _, _| {}).unwrap();
        assert_eq!(stats.events, 2);
        assert_eq!(sys.log.len(), 2, "{:?}", sys.log);
        assert_eq!((sys.log[0].1, sys.log[1].1), (1, 0), "{:?}", sys.log);
        assert!((sys.log[0].0 - 0.4).abs() < 1e-10 && (sys.log[1].0 - 0.55).abs() < 1e-10);
    }

    /// Sliding mode: `x' = -1` while `x > 0`, `x' = +1` while `x < 0`; each event flips the mode
    /// and nudges `x` 1e-11 into the new mode, so events come 1e-11 s apart forever.
    pub struct Chatter {
        pub up: bool,
    }

    impl OdeSystem for Chatter {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = if self.up { 1.0 } else { -1.0 };
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, _t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = if self.up { -x[0] } else { x[0] };
        }
        fn handle_event(&mut self, _t: f64, x: &mut [f64]) -> bool {
            let crossed = if self.up {
                x[0] >= -1e-13
            } else {
                x[0] <= 1e-13
            };
            if crossed {
                self.up = !self.up;
                x[0] = if self.up { -1e-11 } else { 1e-11 };
            }
            crossed
        }
    }

    pub fn check_chatter_is_error(method: &Method) {
        let mut x = [0.25];
        let r = solve(
            method,
            &mut Chatter { up: false },
            &mut x,
            &[0.0, 1.0],
            |_, _, _, _| {},
        );
        match r {
            Err(SolveError::EventLoop { t }) => assert!((t - 0.25).abs() < 1e-8, "t = {t}"),
            other => panic!("expected EventLoop, got {other:?}"),
        }
    }

    /// `x' = 1`, event `0.5 - x`; the handler puts `x` back 1e-13 *below* the limit without a
    /// mode change, so the same event re-crosses 1e-13 s later. That crossing must be ignored.
    pub struct Retrigger;

    impl OdeSystem for Retrigger {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = 1.0;
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, _t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = 0.5 - x[0];
        }
        fn handle_event(&mut self, _t: f64, x: &mut [f64]) -> bool {
            let hit = 0.5 - x[0] <= 1e-9;
            if hit {
                x[0] = 0.5 - 1e-13;
            }
            hit
        }
    }

    pub fn check_retrigger_ignored(method: &Method) {
        let mut x = [0.0];
        let stats = solve(
            method,
            &mut Retrigger,
            &mut x,
            &[0.0, 1.0, 2.0],
            |_, _, _, _| {},
        )
        .unwrap();
        assert_eq!(stats.events, 1);
        assert!((x[0] - 2.0).abs() < 1e-9, "x = {}", x[0]);
    }

    /// `x' = x²`, `x(0) = 1`: `x = 1/(1 - t)` blows up at `t = 1`.
    pub struct Blowup;

    impl OdeSystem for Blowup {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, x: &[f64], dx: &mut [f64]) {
            dx[0] = x[0] * x[0];
        }
    }

    pub fn check_failures(method: &Method) {
        let run = |knots: &[f64]| {
            solve(
                method,
                &mut Oscillator,
                &mut [1.0, 0.0],
                knots,
                |_, _, _, _| {},
            )
        };
        assert!(matches!(
            run(&[0.0, 1.0, 0.5]),
            Err(SolveError::BadKnots { index: 2, .. })
        ));
        assert!(matches!(
            run(&[0.0, 1.0, 1.0]),
            Err(SolveError::BadKnots { index: 2, .. })
        ));
        assert!(matches!(
            run(&[]),
            Err(SolveError::BadKnots { index: 0, .. })
        ));
        assert!(matches!(
            run(&[0.0, f64::NAN]),
            Err(SolveError::BadKnots { index: 1, .. })
        ));
        assert!(matches!(
            run(&[f64::NAN]),
            Err(SolveError::BadKnots { index: 0, .. })
        ));
        assert!(matches!(
            run(&[0.0, f64::INFINITY]),
            Err(SolveError::BadKnots { index: 1, .. })
        ));

        let r = solve(
            method,
            &mut Oscillator,
            &mut [1.0],
            &[0.0, 1.0],
            |_, _, _, _| {},
        );
        assert!(matches!(r, Err(SolveError::BadSetting(_))), "{r:?}");
        let r = solve(
            method,
            &mut Oscillator,
            &mut [1.0, f64::NAN],
            &[0.0, 1.0],
            |_, _, _, _| {},
        );
        assert_eq!(r, Err(SolveError::NonFinite { t: 0.0, state: 1 }));

        let r = solve(
            method,
            &mut Blowup,
            &mut [1.0],
            &[0.0, 2.0],
            |_, _, _, _| {},
        );
        match r {
            Err(SolveError::NonFinite { t, .. } | SolveError::StepUnderflow { t, .. }) => {
                assert!(t > 0.9 && t <= 2.0, "stopped at {t}")
            }
            other => panic!("expected NonFinite or StepUnderflow, got {other:?}"),
        }
    }

    /// The observer sees every knot, in order, with the knot value itself; states are accurate
    /// on a non-uniform grid. A single knot only observes the start.
    pub fn check_observer_knots(method: &Method, tol: f64) {
        let knots = [0.0, 0.013, 0.1, 0.35, 1.0, 1.7, 1.72, 2.0];
        let mut x = Oscillator::exact(0.0);
        let mut seen = Vec::new();
        solve(method, &mut Oscillator, &mut x, &knots, |k, t, x, _| {
            seen.push((k, t, x.to_vec()))
        })
        .unwrap();
        assert_eq!(seen.len(), knots.len());
        for (k, (kk, t, xk)) in seen.iter().enumerate() {
            assert_eq!((*kk, *t), (k, knots[k]));
            let e = max_err(xk, &Oscillator::exact(*t));
            assert!(e < tol, "error {e:e} at t = {t}");
        }

        let mut calls = 0;
        let stats = solve(method, &mut Oscillator, &mut x, &[0.5], |k, t, _, _| {
            assert_eq!((k, t), (0, 0.5));
            calls += 1;
        })
        .unwrap();
        assert_eq!((calls, stats), (1, Stats::default()));
    }

    #[test]
    fn rk4_global_order_is_four() {
        let errs: Vec<f64> = [0.1, 0.05, 0.025]
            .iter()
            .map(|&h| oscillator_error(&Method::Rk4 { h }, &[0.0, 2.0]))
            .collect();
        let p = orders(&errs);
        eprintln!("RK4 errors at t=2 {errs:?}, observed orders {p:.4?}");
        assert!(p.iter().all(|p| (3.8..=4.2).contains(p)), "{p:?}");
    }

    #[test]
    fn rk4_step_local_error_order_five() {
        // One step from the exact state: local error O(h^5).
        let mut work = Rk4Work::new(2);
        let errs: Vec<f64> = [0.2, 0.1, 0.05]
            .iter()
            .map(|&h| {
                let mut out = [0.0; 2];
                rk4_step(
                    &mut Oscillator,
                    0.3,
                    &Oscillator::exact(0.3),
                    h,
                    &mut out,
                    &mut work,
                );
                max_err(&out, &Oscillator::exact(0.3 + h))
            })
            .collect();
        let p = orders(&errs);
        eprintln!("RK4 one-step errors {errs:?}, orders {p:.4?}");
        assert!(p.iter().all(|p| (4.6..=5.4).contains(p)), "{p:?}");
    }

    #[test]
    fn rk4_sub_steps_land_on_knots() {
        assert_eq!(sub_steps(1.0, 0.1), 10);
        assert_eq!(sub_steps(0.1 * 3.0, 0.1), 3); // 0.30000000000000004 / 0.1
        assert_eq!(sub_steps(0.7, 0.3), 3);
        assert_eq!(sub_steps(0.01, 0.3), 1);
        // Counts: 4 evaluations per step, 10 + 1 steps.
        let mut x = Oscillator::exact(0.0);
        let stats = Rk4::new(0.1).unwrap().solve(
            &mut Oscillator,
            &mut x,
            &[0.0, 1.0, 1.05],
            |_, _, _, _| {},
        );
        assert_eq!(
            stats.unwrap(),
            Stats {
                steps_accepted: 11,
                steps_rejected: 0,
                rhs_evals: 44,
                events: 0
            }
        );
    }

    #[test]
    fn rk4_observer_gets_every_knot() {
        check_observer_knots(&Method::Rk4 { h: 0.01 }, 1e-8);
    }

    #[test]
    fn rk4_knot_grid_matches_single_interval_bitwise() {
        // With h = 0.1 both runs take the very same steps, so the result is bit-identical.
        let fine: Vec<f64> = (0..=20).map(|i| i as f64 * 0.1).collect();
        let (mut a, mut b) = (Oscillator::exact(0.0), Oscillator::exact(0.0));
        let m = Method::Rk4 { h: 0.1 };
        solve(&m, &mut Oscillator, &mut a, &[0.0, 2.0], |_, _, _, _| {}).unwrap();
        solve(&m, &mut Oscillator, &mut b, &fine, |_, _, _, _| {}).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn rk4_hermite_is_exact_for_cubics() {
        // x = t^3 - t on [0.5, 1.5]: x' = 3t^2 - 1.
        let (t0, h) = (0.5, 1.0);
        let p = |t: f64| t * t * t - t;
        let dp = |t: f64| 3.0 * t * t - 1.0;
        let mut out = [0.0];
        for theta in [0.0, 0.25, 0.37, 0.9, 1.0] {
            hermite(
                theta,
                h,
                &[p(t0)],
                &[dp(t0)],
                &[p(t0 + h)],
                &[dp(t0 + h)],
                &mut out,
            );
            assert!((out[0] - p(t0 + theta * h)).abs() < 1e-14);
        }
    }

    #[test]
    fn illinois_brackets_the_root() {
        use super::super::illinois;
        type Case = (fn(f64) -> f64, f64); // (g, root)
        let cases: [Case; 3] = [
            (|t| t.cos() - 0.5, std::f64::consts::FRAC_PI_3),
            (|t| (0.7 - t).powi(3), 0.7), // triple root
            (|t| 1e-3 - t * t * t * t, 1e-3f64.powf(0.25)), // flat at the start
        ];
        for (g, root) in cases {
            let mut evals = 0;
            let te = illinois(0.0, g(0.0), 2.0, g(2.0), 1e-12, |t| {
                evals += 1;
                g(t)
            });
            eprintln!(
                "illinois: root {root}, error {:e}, {evals} evaluations",
                te - root
            );
            assert!(
                g(te) <= 0.0 && te >= root && te - root <= 1e-12,
                "{te} vs {root}"
            );
            assert!(evals < 200);
        }
    }

    #[test]
    fn rk4_limiter_event_located_with_coarse_step() {
        check_limiter_pins(&Method::Rk4 { h: 0.3 });
    }

    #[test]
    fn rk4_limiter_holds_and_releases() {
        let (e1, e2, ex) = limiter_release_errors(&Method::Rk4 { h: 0.01 });
        eprintln!("RK4 release: event errors {e1:.2e}, {e2:.2e}; x(3) error {ex:.2e}");
        assert!(e1 < 1e-8 && e2 < 1e-10 && ex < 1e-8, "{e1:e} {e2:e} {ex:e}");
        // The release time depends on t only: exact to the root tolerance even with h = 0.3.
        let (_, e2, _) = limiter_release_errors(&Method::Rk4 { h: 0.3 });
        assert!(e2 < 1e-10, "{e2:e}");
    }

    #[test]
    fn rk4_event_retakes_step_to_event_time() {
        check_turn_retakes_step(&Method::Rk4 { h: 0.3 });
    }

    #[test]
    fn rk4_earliest_of_two_crossings_first() {
        check_earliest_guard_first(&Method::Rk4 { h: 0.3 });
    }

    #[test]
    fn rk4_chattering_modes_are_an_error() {
        check_chatter_is_error(&Method::Rk4 { h: 0.1 });
    }

    #[test]
    fn rk4_retrigger_within_deadband_is_ignored() {
        check_retrigger_ignored(&Method::Rk4 { h: 0.3 });
    }

    #[test]
    fn rk4_errors() {
        check_failures(&Method::Rk4 { h: 0.01 });
        for h in [0.0, -0.1, f64::NAN, f64::INFINITY] {
            assert!(
                matches!(Rk4::new(h), Err(SolveError::BadSetting(_))),
                "h = {h}"
            );
        }
    }

    /// Two decoupled decays at rates 1000 and 1 (1/s) through a rotation, so the fast mode is
    /// not on the diagonal: `x' = R·diag(-1000, -1)·Rᵀ·x`.
    struct Stiff;

    impl OdeSystem for Stiff {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&mut self, _t: f64, x: &[f64], dx: &mut [f64]) {
            let (c, s) = (0.6, 0.8);
            let (a, b) = (c * x[0] + s * x[1], -s * x[0] + c * x[1]);
            let (da, db) = (-1000.0 * a, -b);
            dx[0] = c * da - s * db;
            dx[1] = s * da + c * db;
        }
    }

    /// The start's fastest mode is 1000 1/s: RK4 refuses a step with `h·|λ|` above 2.5 (where
    /// it would amplify the mode ~2 600 times per step at h = 16.7 ms) and integrates the decay
    /// at a step inside the region; the knots' spacing caps the step.
    #[test]
    fn rk4_refuses_a_step_beyond_its_stability_region() {
        let run = |h: f64, knots: &[f64]| {
            let mut x = vec![1.0, 1.0];
            solve(
                &Method::Rk4 { h },
                &mut Stiff,
                &mut x,
                knots,
                |_, _, _, _| {},
            )
            .map(|_| x)
        };
        let rate = fastest_rate(&mut Stiff, 0.0, &[1.0, 1.0]);
        assert!((rate - 1000.0).abs() < 1e-3, "{rate}");
        match run(1.0 / 60.0, &[0.0, 1.0]) {
            Err(SolveError::Stiff { h, rate }) => {
                assert!((h - 1.0 / 60.0).abs() < 1e-15 && (rate - 1000.0).abs() < 1e-3)
            }
            other => panic!("{other:?}"),
        }
        // 2.4 ms: h·|λ| = 2.4, inside; the slow mode decays as e^-t.
        let x = run(2.4e-3, &[0.0, 1.0]).unwrap();
        let b = -0.8 * x[0] + 0.6 * x[1];
        assert!(
            (b - (-0.8f64 + 0.6) * (-1.0f64).exp()).abs() < 1e-6,
            "{x:?}"
        );
        // A long h on knots 1 ms apart takes 1 ms steps: accepted.
        let knots: Vec<f64> = (0..=100).map(|k| k as f64 * 1e-3).collect();
        assert!(run(1.0, &knots).is_ok());
    }

    /// `x' = 1`, reset to 0 whenever it reaches 3 ms: an event every 3 ms, three or four per
    /// 10 ms grid step.
    struct Sawtooth;

    impl OdeSystem for Sawtooth {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) {
            dx[0] = 1.0;
        }
        fn n_events(&self) -> usize {
            1
        }
        fn events(&mut self, _t: f64, x: &[f64], g: &mut [f64]) {
            g[0] = 0.003 - x[0];
        }
        fn handle_event(&mut self, _t: f64, x: &mut [f64]) -> bool {
            if x[0] >= 0.003 - 1e-12 {
                x[0] = 0.0;
                return true;
            }
            false
        }
    }

    /// Modes switching several times within every step exhaust RK4's budget (twice the grid's
    /// steps plus 100) and fail instead of being located one by one without bound; one switch
    /// every two steps fits.
    #[test]
    fn rk4_fails_modes_switching_within_every_step() {
        let mut x = vec![0.0];
        match solve(
            &Method::Rk4 { h: 0.01 },
            &mut Sawtooth,
            &mut x,
            &[0.0, 10.0],
            |_, _, _, _| {},
        ) {
            Err(SolveError::TooManySteps { max_steps, .. }) => assert_eq!(max_steps, 2_100),
            other => panic!("{other:?}"),
        }
        let mut x = vec![0.0];
        let stats = solve(
            &Method::Rk4 { h: 0.0015 },
            &mut Sawtooth,
            &mut x,
            &[0.0, 1.0],
            |_, _, _, _| {},
        )
        .unwrap();
        assert!(stats.events >= 300, "{stats:?}");
    }
}
