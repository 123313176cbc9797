//! The sensitivity playback: the unit's states and their derivatives with respect to chosen
//! parameters, integrated together on one step sequence, and P, Q with their derivatives at
//! every sample.
//!
//! **Equations.** With `ẋ = f(t, x, p)` the unit's right-hand side and `S = ∂x/∂p`, the
//! augmented state `[x, S]` obeys `ẋ = f`, `Ṡ = ∂f/∂x S + ∂f/∂p`; evaluating `f` on duals
//! `x + S ε`, `p + e ε` gives both exactly. P and Q come out of the same dual evaluation at every
//! sample, so `∂P/∂p = ∂P/∂x S + ∂P/∂p`.
//!
//! **Steps.** The sensitivities are integrated on the steps the plain adaptive playback took
//! (its step log, replayed without error control: [`crate::integrate::Method::Replay`]), so the
//! derivative is that of the discretised playback the fit sees, free of step-size noise; a
//! fixed-step method (RK4) is used as given.
//!
//! **Initialisation.** `x(0)` solves the steady state at the measured operating point, and it
//! moves with the parameters (a larger X_d asks for a larger E_fd0). Its derivative, and that of
//! every signal the initialisation leaves on the bus and of every block's
//! [`crate::Block::init_constants`], is the central difference of the initialisation (closed
//! forms and converged Newton solves, microseconds each: truncation error ~1e-10 relative;
//! where the lower point is outside a parameter's domain, a second-order one-sided difference).
//!
//! **Discrete modes.** The modes (a non-windup limit pinned or free) switch where the plain
//! playback's do, on the values; while a mode holds, the derivative is that of the active
//! branch, and a state pinned to a limit takes the limit's derivatives ([`crate::Block::pin_dual`]).
//!
//! **Static switches.** A piecewise right-hand side whose pieces switch without a guard (a
//! diagram's `switch`, `deadband`, `limiter`, `min`/`max`, `pwl`) takes the derivative of the
//! active piece at every evaluation: the sensitivities are those of the replayed discrete
//! playback, which differ from the converged derivative by the share of the steps that
//! straddle a switch.
//!
//! **Limits of this version.** A unit whose blocks do not all have dual equations or an event
//! with set-point steps is refused with [`SensError::Unsupported`]; the caller falls back to
//! differences.

use super::{Scalar, D, LANES};
use crate::integrate::{self, Dopri5Options, Method, OdeSystem, StepLog};
use crate::simulate::{simulate_pq, PreparedEvent, SimError, SimOptions};
use crate::unit::{ParamRef, PlaybackInput, Unit, UnitError};

/// Why no sensitivities were computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensError {
    /// The unit or event is outside what the dual equations cover (the reason says what).
    #[error("no forward sensitivities: {0}")]
    Unsupported(String),
    /// The playback itself failed.
    #[error(transparent)]
    Sim(#[from] SimError),
}

impl From<UnitError> for SensError {
    fn from(e: UnitError) -> Self {
        SensError::Sim(SimError::Init(e))
    }
}

/// P and Q [pu system base] at every sample and their derivatives with respect to each
/// requested parameter (`dp[j][k] = ∂P_k/∂p_j`); the field channels E_fd and X_ad I_fd [pu
/// machine base] likewise, as the phasor playback's [`crate::mode::simulate_mode`] reads them
/// (empty where the unit has no such signal).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PqSensitivities {
    pub p: Vec<f64>,
    pub q: Vec<f64>,
    pub dp: Vec<Vec<f64>>,
    pub dq: Vec<Vec<f64>>,
    pub efd: Vec<f64>,
    pub ifd: Vec<f64>,
    pub defd: Vec<Vec<f64>>,
    pub difd: Vec<Vec<f64>>,
}

/// One pass's values and derivatives, or the concatenation of passes.
impl PqSensitivities {
    /// Appends `other`'s derivative columns (the next parameters), taking its values if these
    /// are still empty.
    pub fn extend(&mut self, other: PqSensitivities) {
        if self.p.is_empty() {
            (self.p, self.q) = (other.p, other.q);
            (self.efd, self.ifd) = (other.efd, other.ifd);
        }
        self.dp.extend(other.dp);
        self.dq.extend(other.dq);
        self.defd.extend(other.defd);
        self.difd.extend(other.difd);
    }
}

/// P, Q and `∂P/∂p`, `∂Q/∂p` of the phasor playback of `ev` through `unit` (as
/// [`simulate_pq`] computes P and Q), for the parameters `params`; E_fd and X_ad I_fd with
/// theirs too (as [`crate::mode::simulate_mode`]'s phasor playback reads them; with no
/// parameter, P and Q alone).
pub fn simulate_pq_sensitivities(
    unit: &Unit,
    ev: &PreparedEvent,
    params: &[ParamRef],
    opts: &SimOptions,
) -> Result<PqSensitivities, SensError> {
    if !ev.has_angle {
        return Err(SimError::NoAngle {
            event: ev.name.clone(),
        }
        .into());
    }
    if !ev.steps.is_empty() {
        return Err(SensError::Unsupported(format!(
            "event '{}' has set-point steps (a mode playback)",
            ev.name
        )));
    }
    ev.check_frequency(unit)?;
    // The step sequence: the plain adaptive playback's, logged.
    let method = match &opts.method {
        Method::Rk4 { .. } | Method::Replay(_) => opts.method.clone(),
        Method::Dopri5(o) | Method::Dopri5Logged(o, _) => logged_steps(unit, ev, o)?,
    };
    let mut out = PqSensitivities::default();
    for chunk in params.chunks(LANES) {
        out.extend(pass(unit, ev, chunk, &method)?);
    }
    if params.is_empty() {
        let (p, q) = simulate_pq(&mut unit.clone(), ev, &SimOptions { method })?;
        (out.p, out.q) = (p, q);
    }
    Ok(out)
}

/// The steps of the plain Dormand-Prince playback, as a replay schedule.
fn logged_steps(unit: &Unit, ev: &PreparedEvent, o: &Dopri5Options) -> Result<Method, SimError> {
    let log = StepLog::default();
    let opts = SimOptions {
        method: Method::Dopri5Logged(o.clone(), log.clone()),
    };
    simulate_pq(&mut unit.clone(), ev, &opts)?;
    Ok(Method::Replay(log.times()))
}

/// The initialisation's outputs: the state, the bus, every block's constants.
struct Init {
    x: Vec<f64>,
    bus: Vec<f64>,
    consts: Vec<Vec<f64>>,
}

impl Init {
    fn of(unit: &mut Unit, ev: &PreparedEvent) -> Result<Self, UnitError> {
        let x = unit.initialise(&ev.machine_point(unit))?;
        Ok(Self {
            x,
            bus: unit.bus().to_vec(),
            consts: unit.init_constants(),
        })
    }

    /// Every number, flattened (state, bus, constants).
    fn flat(&self) -> Vec<f64> {
        let mut v = self.x.clone();
        v.extend_from_slice(&self.bus);
        for c in &self.consts {
            v.extend_from_slice(c);
        }
        v
    }
}

/// The derivative of the initialisation with respect to parameter `r`: central difference,
/// or the second-order one-sided one when the lower point does not initialise.
fn init_tangent(unit: &Unit, ev: &PreparedEvent, r: ParamRef) -> Result<Vec<f64>, SensError> {
    let p0 = unit.get(r);
    // A step the parameter's plausible range measures (a parameter may be 0: D, T_C1).
    let (lo, hi) = unit.param_spec(r).range;
    let h = 1e-6 * p0.abs().max(0.1 * (hi - lo)).max(1e-6);
    let at = |v: f64| -> Result<Vec<f64>, UnitError> {
        let mut u = unit.clone();
        u.set(r, v);
        Ok(Init::of(&mut u, ev)?.flat())
    };
    let up = at(p0 + h)?;
    match at(p0 - h) {
        Ok(dn) => Ok(up
            .iter()
            .zip(&dn)
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect()),
        Err(_) => {
            let (f0, f2) = (at(p0)?, at(p0 + 2.0 * h)?);
            // (4 (f1 − f0) − (f2 − f0))/(2h): exactly 0 where the initialisation does not move.
            Ok((0..f0.len())
                .map(|i| (4.0 * (up[i] - f0[i]) - (f2[i] - f0[i])) / (2.0 * h))
                .collect())
        }
    }
}

/// One pass: up to [`LANES`] parameters on the tangent lanes.
fn pass(
    unit: &Unit,
    ev: &PreparedEvent,
    params: &[ParamRef],
    method: &Method,
) -> Result<PqSensitivities, SensError> {
    let mut u = unit.clone();
    let init = Init::of(&mut u, ev)?;
    // Tangents of the initialisation, one lane per parameter.
    let tangents: Vec<Vec<f64>> = params
        .iter()
        .map(|&r| init_tangent(unit, ev, r))
        .collect::<Result<_, _>>()?;
    let dual_of = |offset: usize, v: f64| {
        let mut d = [0.0; LANES];
        for (k, t) in tangents.iter().enumerate() {
            d[k] = t[offset];
        }
        D::new(v, d)
    };
    let (n, nb) = (init.x.len(), init.bus.len());
    let bus: Vec<D> = (0..nb).map(|i| dual_of(n + i, init.bus[i])).collect();
    let mut off = n + nb;
    let mut consts = Vec::with_capacity(init.consts.len());
    for c in &init.consts {
        consts.push(
            c.iter()
                .enumerate()
                .map(|(i, &v)| dual_of(off + i, v))
                .collect::<Vec<_>>(),
        );
        off += c.len();
    }
    let mut lanes: Vec<Vec<Option<usize>>> = u
        .instances()
        .iter()
        .map(|i| vec![None; i.block.params().specs().len()])
        .collect();
    for (k, r) in params.iter().enumerate() {
        lanes[r.block][r.index] = Some(k);
    }
    u.seed_dual(&lanes, &consts)
        .map_err(|b| SensError::Unsupported(format!("block {b} has no dual equations")))?;
    // The augmented state [x, S] (S row-major: state i's lanes at n + i·LANES).
    let mut xa = vec![0.0; n * (1 + LANES)];
    for i in 0..n {
        let xi = dual_of(i, init.x[i]);
        xa[i] = xi.v;
        xa[n + i * LANES..n + (i + 1) * LANES].copy_from_slice(&xi.d);
    }
    let (ip, iq) = u.pq_signals()?;
    let (iefd, iifd) = crate::mode::field_signals(&u);
    let ns = ev.input.time_s.len();
    let to_sys = u.machine_mva / ev.system_mva;
    let np = params.len();
    let (mut pd, mut qd) = (vec![D::cst(0.0); ns], vec![D::cst(0.0); ns]);
    let field = |i: Option<usize>| vec![D::cst(0.0); if i.is_some() { ns } else { 0 }];
    let (mut ed, mut fd) = (field(iefd), field(iifd));
    let mut sys = Augmented::new(&mut u, &ev.input, bus);
    integrate::solve(
        method,
        &mut sys,
        &mut xa,
        &ev.input.time_s,
        |k, t, xa, sys| {
            sys.eval(t, xa);
            // What the PMU records: the machine's output less any terminal load at the bus
            // voltage.
            let (pl, ql) = sys.unit.terminal_load_dual(sys.bus[sys.sig.0].v);
            pd[k] = (sys.bus[ip] - pl) * to_sys;
            qd[k] = (sys.bus[iq] - ql) * to_sys;
            if let Some(i) = iefd {
                ed[k] = sys.bus[i];
            }
            if let Some(i) = iifd {
                fd[k] = sys.bus[i];
            }
        },
    )
    .map_err(SimError::from)?;
    // The measuring device's transform (skew, phase and ratio errors), its parameters' part
    // included.
    u.transform_pq_dual(&ev.input.time_s, &mut pd, &mut qd);
    let values = |s: &[D]| s.iter().map(|v| v.v).collect::<Vec<f64>>();
    // One column per parameter; none for a channel the unit does not have.
    let columns = |s: &[D]| -> Vec<Vec<f64>> {
        if s.is_empty() {
            return vec![];
        }
        (0..np)
            .map(|j| s.iter().map(|v| v.d[j]).collect())
            .collect()
    };
    Ok(PqSensitivities {
        p: values(&pd),
        q: values(&qd),
        dp: columns(&pd),
        dq: columns(&qd),
        efd: values(&ed),
        ifd: values(&fd),
        defd: columns(&ed),
        difd: columns(&fd),
    })
}

/// The unit's states and sensitivities as one ODE.
struct Augmented<'a> {
    unit: &'a mut Unit,
    input: &'a PlaybackInput,
    cursor: usize,
    sig: (usize, usize),
    bus: Vec<D>,
    x: Vec<D>,
    dx: Vec<D>,
    /// The point `(t, [x, S])` the dual bus was last evaluated at (the sample observer reads
    /// the bus the step's last stage evaluated, as the plain [`crate::unit::Playback`] does).
    bus_t: f64,
    bus_xa: Vec<f64>,
    bus_valid: bool,
    /// Whether the driver's first call of `handle_event` (before the first step) is done.
    started: bool,
}

impl<'a> Augmented<'a> {
    fn new(unit: &'a mut Unit, input: &'a PlaybackInput, bus: Vec<D>) -> Self {
        let n = unit.n_states();
        let sig = unit.terminal_signals();
        Self {
            unit,
            input,
            cursor: 0,
            sig,
            bus,
            x: vec![D::cst(0.0); n],
            dx: vec![D::cst(0.0); n],
            bus_t: 0.0,
            bus_xa: vec![0.0; n * (1 + LANES)],
            bus_valid: false,
            started: false,
        }
    }

    /// The dual bus at `(t, [x, S])`.
    #[inline]
    fn eval(&mut self, t: f64, xa: &[f64]) {
        if self.bus_valid && t == self.bus_t && xa == self.bus_xa.as_slice() {
            return;
        }
        let n = self.x.len();
        for i in 0..n {
            let mut d = [0.0; LANES];
            d.copy_from_slice(&xa[n + i * LANES..n + (i + 1) * LANES]);
            self.x[i] = D::new(xa[i], d);
        }
        let (v, th) = self.input.at(t, &mut self.cursor);
        self.bus[self.sig.0] = D::cst(v);
        self.bus[self.sig.1] = D::cst(th);
        self.unit.eval_outputs_dual(t, &self.x, &mut self.bus);
        self.bus_t = t;
        self.bus_xa.copy_from_slice(xa);
        self.bus_valid = true;
    }

    /// The plain unit's signals at `(t, x)` (for its event functions and modes).
    fn eval_plain(&mut self, t: f64, x: &[f64]) {
        let (v, th) = self.input.at(t, &mut self.cursor);
        self.unit.set_terminal_voltage(v, th);
        self.unit.eval_outputs(t, x);
    }
}

impl OdeSystem for Augmented<'_> {
    fn dim(&self) -> usize {
        self.x.len() * (1 + LANES)
    }
    fn rhs(&mut self, t: f64, xa: &[f64], dxa: &mut [f64]) {
        self.eval(t, xa);
        self.unit
            .eval_derivatives_dual(t, &self.x, &mut self.bus, &mut self.dx);
        let n = self.x.len();
        for i in 0..n {
            dxa[i] = self.dx[i].v;
            dxa[n + i * LANES..n + (i + 1) * LANES].copy_from_slice(&self.dx[i].d);
        }
    }
    fn n_events(&self) -> usize {
        self.unit.n_events()
    }
    fn events(&mut self, t: f64, xa: &[f64], g: &mut [f64]) {
        let n = self.x.len();
        self.eval_plain(t, &xa[..n]);
        self.unit.eval_events(&xa[..n], g);
    }
    /// The modes switch on the values alone, where the plain playback's do. The sensitivities
    /// jump there (the saltation of a hybrid system): with `t*(p)` the time the guard `g` that
    /// fired crosses zero,
    ///
    /// ```text
    /// ∂t*/∂p = −(∂g/∂x S⁻ + ∂g/∂p) / (∂g/∂x f⁻ + ∂g/∂t)
    /// S⁺     = S⁻ + (f⁻ − f⁺) ∂t*/∂p,   then a state the new mode pins: its limit's derivatives
    /// ```
    ///
    /// (`f⁻`, `f⁺` the right-hand sides before and after the switch). The numerator is the
    /// guard on dual numbers ([`crate::Block::events_dual`]); the denominator, the guard's rate
    /// along the trajectory, a central difference on the plain system in the old modes (δ =
    /// 1e-6 s: truncation δ²·g‴/6 and rounding ~1e-16/δ, both below 1e-8 of the rate). A
    /// state pinned to a limit then takes the limit's value and derivatives
    /// ([`crate::Block::pin_dual`], the reset's derivative), which for a non-windup limit on a
    /// constant limit is the whole of the jump (the other states' right-hand sides are
    /// continuous across it): where a block's guards have no dual form only the pin is applied.
    fn handle_event(&mut self, t: f64, xa: &mut [f64]) -> bool {
        let n = self.x.len();
        // The guard that fired (the driver calls here when one went ≤ 0; the call before the
        // first step is not a crossing).
        let shift = if std::mem::replace(&mut self.started, true) {
            self.crossing_shift(t, xa)
        } else {
            None
        };
        let f_minus = shift.as_ref().map(|_| self.plain_rhs(t, &xa[..n]));
        // The states pinned to a moving limit before the switch: the limit on duals and its
        // rate along the trajectory (for a release, below).
        let pinned = match &f_minus {
            Some(fm) => self.moving_pins(t, xa, fm),
            None => Vec::new(),
        };
        self.eval_plain(t, &xa[..n]);
        let changed = self.unit.update_modes(&mut xa[..n]);
        // The modes (and perhaps x) changed: the outputs are evaluated again.
        self.bus_valid = false;
        // The rates in the new modes (for the saltation and a release's reset).
        let f_plus = shift.map(|_| self.plain_rhs(t, &xa[..n]));
        if let (Some(tau), Some(fm), Some(fp)) = (shift, f_minus, &f_plus) {
            for i in 0..n {
                let jump = fm[i] - fp[i];
                if jump != 0.0 {
                    for (l, tl) in tau.iter().enumerate() {
                        xa[n + i * LANES + l] += jump * tl;
                    }
                }
            }
        }
        self.eval(t, xa);
        self.unit.pin_dual(&mut self.x, &mut self.bus);
        if let (Some(tau), Some(fp), false) = (shift, &f_plus, pinned.is_empty()) {
            // A state released from a moving limit was projected onto it, `x⁺ = L(t*)`:
            // `S⁺ = dL/dp + (L̇ − f⁺) ∂t*/∂p`, the limit's derivatives at the switch plus its
            // rate along the trajectory times the switch time's shift, less the new rate's.
            let mut still = Vec::new();
            self.eval_plain(t, &xa[..n]);
            self.unit.eval_moving_pins(&xa[..n], &mut still);
            for (i, lim, rate) in pinned {
                if still.iter().any(|&(j, _)| j == i) {
                    continue;
                }
                for (l, tl) in tau.iter().enumerate() {
                    self.x[i].d[l] = lim.d[l] + (rate - fp[i]) * tl;
                }
            }
        }
        for i in 0..n {
            xa[i] = self.x[i].v;
            xa[n + i * LANES..n + (i + 1) * LANES].copy_from_slice(&self.x[i].d);
        }
        self.bus_valid = false;
        changed
    }
}

impl Augmented<'_> {
    /// The plain right-hand side at `(t, x)` in the current modes.
    fn plain_rhs(&mut self, t: f64, x: &[f64]) -> Vec<f64> {
        let mut f = vec![0.0; x.len()];
        self.eval_plain(t, x);
        self.unit.eval_derivatives(t, x, &mut f);
        f
    }

    /// The states pinned to a moving limit at `(t, [x, S])` in the modes before a switch
    /// ([`crate::Block::moving_pins`]): `(state, the limit on duals, its rate along the
    /// trajectory)`, the rate a central difference over `t ± δ` with the states moved by `f`
    /// (δ = 1e-6 s, as for the guards' rates in [`Augmented::crossing_shift`]).
    fn moving_pins(&mut self, t: f64, xa: &[f64], f: &[f64]) -> Vec<(usize, D, f64)> {
        let n = self.x.len();
        let mut now = Vec::new();
        self.eval_plain(t, &xa[..n]);
        self.unit.eval_moving_pins(&xa[..n], &mut now);
        if now.is_empty() {
            return Vec::new();
        }
        let delta = 1e-6;
        let mut at = |s: f64| {
            let x: Vec<f64> = (0..n).map(|i| xa[i] + s * delta * f[i]).collect();
            self.eval_plain(t + s * delta, &x);
            let mut v = Vec::new();
            self.unit.eval_moving_pins(&x, &mut v);
            v
        };
        let (up, dn) = (at(1.0), at(-1.0));
        self.eval(t, xa);
        let mut duals = Vec::new();
        self.unit
            .eval_moving_pins_dual(&self.x, &mut self.bus, &mut duals);
        now.iter()
            .filter_map(|&(i, _)| {
                let u = up.iter().find(|p| p.0 == i)?.1;
                let d = dn.iter().find(|p| p.0 == i)?.1;
                let lim = duals.iter().find(|p| p.0 == i)?.1;
                Some((i, lim, (u - d) / (2.0 * delta)))
            })
            .collect()
    }

    /// `∂t*/∂p` on every lane for the guard that went ≤ 0 at `(t, [x, S])` (the most negative
    /// one), in the modes before the switch; `None` when none did, its block has no dual
    /// guards, or the trajectory grazes it (a rate of 0: no finite shift).
    fn crossing_shift(&mut self, t: f64, xa: &[f64]) -> Option<[f64; LANES]> {
        let n = self.x.len();
        let ne = self.unit.n_events();
        if ne == 0 {
            return None;
        }
        let mut g = vec![0.0; ne];
        self.eval_plain(t, &xa[..n]);
        self.unit.eval_events(&xa[..n], &mut g);
        let k = (0..ne)
            .filter(|&k| g[k] <= 0.0)
            .min_by(|&a, &b| g[a].total_cmp(&g[b]))?;
        self.eval(t, xa);
        let mut gd = vec![D::cst(0.0); ne];
        self.unit.eval_events_dual(&self.x, &mut self.bus, &mut gd);
        if !gd[k].v.is_finite() {
            return None;
        }
        // The guard's rate along the trajectory, modes frozen.
        let f = self.plain_rhs(t, &xa[..n]);
        let delta = 1e-6;
        let mut at = |s: f64| {
            let x: Vec<f64> = (0..n).map(|i| xa[i] + s * delta * f[i]).collect();
            self.eval_plain(t + s * delta, &x);
            self.unit.eval_events(&x, &mut g);
            g[k]
        };
        let rate = (at(1.0) - at(-1.0)) / (2.0 * delta);
        if !(rate.abs() > 0.0 && rate.is_finite()) {
            return None;
        }
        let mut tau = [0.0; LANES];
        for (l, v) in tau.iter_mut().enumerate() {
            *v = -gd[k].d[l] / rate;
        }
        Some(tau)
    }
}
