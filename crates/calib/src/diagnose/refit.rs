//! The re-fit every candidate, baseline and the reference is: a grid scan of the narrow-valleyed
//! parameters, the swarm, the scan again, L-BFGS (then a polish over the polish-only ones), and
//! its χ² on the fitted and held-out samples; the standard errors of the named cause; the
//! `refit` bounds of calibrated parameters freed again.

use crate::bounds::{FreeBound, PriorSource};
use crate::evidence;
use crate::fit::{search, FitOptions, Progress};
use crate::problem::{
    accurate_integrator, refit_search_integrator, search_integrator, sum_of_squares, EventData,
    FreeParam, Problem, SimulatedPq, WindowSums,
};
use crate::spec::{Compare, Strategy};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::unit::{ParamRef, Unit};

use super::error::RefitError;
use super::options::DiagnoseOptions;
use super::profile::{Label, Profile};
use super::split::Split;

/// A candidate's re-fit with the bounds and ties it was re-fitted over (for its standard errors).
pub(super) type RefitRecord = (Refit, Vec<FreeBound>, Vec<(String, String)>);

/// Largest RK4 step of the re-fits' L-BFGS phase [s] (a calibration uses 2 ms). Every re-fit's
/// χ² is taken with the accurate integrator, so the local phase only has to lead downhill, which
/// a step of at most half the smallest time constant does (RK4's stability and accuracy there).
pub(super) const REFIT_RK4_STEP_MAX_S: f64 = 5e-3;

/// Largest grid product scanned jointly (simulations) before falling back to one-at-a-time
/// scans (the largest the catalog asks for: the exciter ceiling's 24 points by T_E's 8 and its
/// datasheet value, 216).
pub(super) const MAX_JOINT_SCAN: usize = 240;

/// Outcome of one re-fit.
#[derive(Clone)]
pub(super) struct Refit {
    pub(super) values: Vec<f64>,
    pub(super) unit: Unit,
    pub(super) chi2_fit: f64,
    pub(super) chi2_held: f64,
    /// The priors' part of both χ² (the same rows in each: the values are the same).
    pub(super) chi2_prior: f64,
    pub(super) n_fit: usize,
    pub(super) n_held: usize,
    pub(super) simulations: usize,
    pub(super) failures: usize,
    /// Variance inflation of the fitted residual, `(1 + ρ₁)/(1 − ρ₁)` (AR(1) approximation).
    pub(super) vif: f64,
    /// RMS of each compared channel (P and Q in the phasor playback; [`Playback::channels`])
    /// [pu] over every sample of the fitted events (the fitted and held-out blocks both;
    /// held-out events apart), from the same accurate simulation as the χ².
    pub(super) rms: Vec<f64>,
}

/// The scores of a re-fit (without its unit and values).
#[derive(Clone, Copy)]
pub(super) struct Scores {
    pub(super) chi2_fit: f64,
    pub(super) chi2_held: f64,
    pub(super) chi2_prior: f64,
    pub(super) vif: f64,
}

impl Scores {
    /// The fitted and held-out χ² without the priors' rows.
    pub(super) fn residuals_chi2(&self) -> (f64, f64) {
        (
            self.chi2_fit - self.chi2_prior,
            self.chi2_held - self.chi2_prior,
        )
    }
}

impl Refit {
    /// `other` in this re-fit's place, with both re-fits' simulations counted.
    pub(super) fn replaced_by(self, other: Refit) -> Refit {
        Refit {
            simulations: self.simulations + other.simulations,
            ..other
        }
    }

    /// The better (lower fitted χ²) of this re-fit and `other` when `other` ran, with both
    /// re-fits' simulations counted; this one when `other` failed.
    pub(super) fn best_of(mut self, other: Result<Refit, RefitError>) -> Refit {
        match other {
            Ok(o) if o.chi2_fit < self.chi2_fit => self.replaced_by(o),
            Ok(o) => {
                self.simulations += o.simulations;
                self
            }
            Err(_) => self,
        }
    }

    pub(super) fn clone_scores(&self) -> Scores {
        Scores {
            chi2_fit: self.chi2_fit,
            chi2_held: self.chi2_held,
            chi2_prior: self.chi2_prior,
            vif: self.vif,
        }
    }
}

/// `(1 + ρ₁)/(1 − ρ₁)` from the lag-1 autocorrelation of the P and Q residual series
/// (interleaved in `r`), ρ₁ clamped to [0, 0.9]: how much a χ² difference overstates the
/// evidence when the residual is not white.
pub(super) fn variance_inflation(r: &[f64], channels: usize) -> f64 {
    let mut rho = 0.0;
    for c in 0..channels {
        let x: Vec<f64> = r.iter().skip(c).step_by(channels).copied().collect();
        rho += evidence::autocorrelation(&x, 1)
            .first()
            .copied()
            .unwrap_or(0.0)
            / channels as f64;
    }
    let rho = rho.clamp(0.0, 0.9);
    (1.0 + rho) / (1.0 - rho)
}

/// `bounds` resolved in `unit` with their own priors ([`crate::bounds::resolve`]); the error
/// holds the problem's text (a re-fit's note).
pub(super) fn resolve(unit: &Unit, bounds: &[FreeBound]) -> Result<Vec<FreeParam>, RefitError> {
    crate::bounds::resolve(unit, bounds, PriorSource::Given)
        .map_err(|e| RefitError::Setup(e.problem.to_string()))
}

/// Grid scan of the parameters `scans` (`(index in problem.free, points)`) from the problem's
/// start: jointly on their grid product when it is small (limits and time constants that trade
/// against each other along a curved valley), otherwise one at a time with the others at their
/// start. The best grid point becomes the start when it improves on it.
pub(super) fn scan(problem: &mut Problem, scans: &[(usize, usize)], sim: &SimOptions) {
    let scanned: Vec<(usize, Vec<f64>)> = scans
        .iter()
        .map(|&(jj, n)| {
            let f = &problem.free[jj];
            let mut grid: Vec<f64> = (0..n)
                .map(|i| f.from_unit(i as f64 / (n - 1) as f64))
                .collect();
            // The datasheet value is a grid point too: a calibration that bent the parameter
            // to mimic the missing effect left it off the valley the extension lies in.
            if let Some(c) = f
                .prior
                .map(|p| p.center)
                .filter(|c| (f.lo..=f.hi).contains(c))
            {
                grid.push(c);
            }
            (jj, grid)
        })
        .collect();
    let product: usize = scanned.iter().map(|(_, g)| g.len()).product();
    let groups: Vec<Vec<&(usize, Vec<f64>)>> = if scanned.len() > 1 && product <= MAX_JOINT_SCAN {
        vec![scanned.iter().collect()]
    } else {
        scanned.iter().map(|s| vec![s]).collect()
    };
    for group in groups {
        let size: usize = group.iter().map(|(_, g)| g.len()).product();
        let base = problem.start();
        let start_cost = problem.cost(&base, sim);
        let points: Vec<Vec<f64>> = (0..size)
            .map(|mut k| {
                let mut xs = base.clone();
                for (jj, g) in &group {
                    xs[*jj] = g[k % g.len()];
                    k /= g.len();
                }
                xs
            })
            .collect();
        // Only a point below the start is taken: the others stop once they cannot be.
        let (c, i) = problem.best_of_below(&points, sim, start_cost);
        if c < start_cost {
            for (jj, _) in &group {
                problem.free[*jj].start = points[i][*jj];
            }
        }
    }
}

/// What every re-fit of a diagnosis shares: the samples it fits and judges (the record's split,
/// or its surrogate's), the noise weights, the options and where progress goes.
#[derive(Clone, Copy)]
pub(super) struct RefitEnv<'a> {
    pub(super) sp: &'a Split,
    pub(super) weights: (f64, f64),
    /// A playback mode's compared channels and their noise weights (`None`: the phasor
    /// playback, P and Q weighted by `weights`).
    pub(super) compare: Option<&'a Compare>,
    pub(super) opts: &'a DiagnoseOptions,
    pub(super) progress: &'a dyn Progress,
    /// Where the re-fits' time goes (`None`: not kept).
    pub(super) profile: Option<&'a Profile>,
}

impl<'a> RefitEnv<'a> {
    /// The same re-fits on the samples `sp` (the surrogate's, say).
    pub(super) fn on(self, sp: &'a Split) -> Self {
        Self { sp, ..self }
    }

    /// The same re-fits with the options `opts` (a longer swarm, or none).
    pub(super) fn with(self, opts: &'a DiagnoseOptions) -> Self {
        Self { opts, ..self }
    }

    /// A re-fit's problem over `data`: the noise weights, the compared channels, the ties and
    /// the priors' weight every re-fit uses.
    pub(super) fn problem(
        &self,
        unit: Unit,
        free: Vec<FreeParam>,
        data: Vec<EventData>,
        ties: &[(ParamRef, ParamRef)],
    ) -> Problem {
        problem_for(unit, free, data, self.weights, self.compare, ties)
    }
}

/// [`RefitEnv::problem`] without an environment.
fn problem_for(
    unit: Unit,
    free: Vec<FreeParam>,
    data: Vec<EventData>,
    weights: (f64, f64),
    compare: Option<&Compare>,
    ties: &[(ParamRef, ParamRef)],
) -> Problem {
    let mut p = Problem::new(unit, free, data, weights);
    p.compare = compare.cloned();
    p.ties = ties.to_vec();
    p.prior_weight = PRIOR_WEIGHT;
    p
}

/// One re-fit of `unit` over `bounds` (with `ties`) on `env`'s samples: the global search
/// ([`RefitRun::search`]: scan, swarm, scan again, the local method) over the parameters that
/// are not polish-only, then the local method over every parameter when some are
/// ([`RefitRun::polish`]), then the χ² of the fitted and held-out samples with the accurate
/// integrator ([`RefitRun::score`]).
pub(super) fn refit(
    env: &RefitEnv,
    unit: &Unit,
    bounds: &[FreeBound],
    ties: &[(String, String)],
    label: &Label,
) -> Result<Refit, RefitError> {
    let opts = env.opts;
    // The searches' playbacks ([`DiagnoseOptions::refit_over_samples`]).
    let search_sim = if opts.refit_over_samples {
        refit_search_integrator()
    } else {
        search_integrator()
    };
    let run = RefitRun {
        env,
        kind: label.kind.name(),
        label: label.text.as_str(),
        fit_opts: search_options(opts, &search_sim),
        search_sim,
    };
    let t_refit = std::time::Instant::now();
    if opts.cancelled() {
        return Err(RefitError::Interrupted);
    }
    let free = resolve(unit, bounds)?;
    let tie_refs = tie_refs(unit, ties)?;
    let mut x: Vec<f64> = free.iter().map(|f| f.start).collect();
    let (mut simulations, mut failures) = (0, 0);
    let global: Vec<usize> = (0..bounds.len())
        .filter(|&j| !bounds[j].polish_only)
        .collect();
    if !global.is_empty() {
        let (best, sims, fails) = run.search(unit, &free, bounds, &global, &tie_refs);
        for (jj, &j) in global.iter().enumerate() {
            x[j] = best[jj];
        }
        (simulations, failures) = (simulations + sims, failures + fails);
    }
    if global.len() < bounds.len() {
        let (best, sims, fails) = run.polish(unit, &free, &x, &tie_refs);
        x = best;
        (simulations, failures) = (simulations + sims, failures + fails);
    }
    if opts.cancelled() {
        return Err(RefitError::Interrupted);
    }
    let refit = run.score(unit, free, x, &tie_refs, simulations, failures)?;
    if let Some(p) = env.profile {
        p.add(
            run.kind,
            "whole re-fit",
            t_refit.elapsed().as_secs_f64(),
            0,
            1,
        );
    }
    Ok(refit)
}

/// The search settings of every re-fit: the diagnosis's swarm and local method, one pass.
fn search_options(opts: &DiagnoseOptions, search_sim: &SimOptions) -> FitOptions {
    FitOptions {
        stages: vec![],
        strategy: Strategy::Sequential,
        seed: opts.seed,
        particles: opts.particles,
        pso_iterations: opts.pso_iterations,
        lbfgs_iterations: opts.lbfgs_iterations,
        lbfgs_memory: opts.lbfgs_memory,
        lbfgs_step_max_s: REFIT_RK4_STEP_MAX_S,
        polish: false,
        local: crate::spec::LocalMethod::Lm,
        lm_stop: crate::local::LmStop::COMPARISON,
        // A re-fit's swarm hands its best alone to the local method (the thresholds were set
        // on that search; a baseline and its extension are searched alike).
        local_starts: 1,
        // No joint pass: a re-fit is one pass (`polish` off).
        joint_pso_iterations: None,
        swarm_integrator: search_sim.clone(),
    }
}

/// One re-fit's phases, with where their time goes ([`Profile`]).
struct RefitRun<'r> {
    env: &'r RefitEnv<'r>,
    /// The profile's name of the re-fit's kind ([`super::profile::RefitKind::name`]).
    kind: &'static str,
    /// The re-fit's name in progress messages.
    label: &'r str,
    fit_opts: FitOptions,
    search_sim: SimOptions,
}

impl RefitRun<'_> {
    /// Adds a phase's time and simulations to the profile.
    fn record(&self, phase: &str, wall_s: f64, simulations: usize) {
        if let Some(p) = self.env.profile {
            p.add(self.kind, phase, wall_s, simulations, 0);
        }
    }

    /// The search phases' own times.
    fn record_phases(&self, phases: &[crate::fit::PhaseReport]) {
        for ph in phases {
            let name = if ph.phase == "pso" { "swarm" } else { "local" };
            self.record(name, ph.wall_s, ph.simulations);
        }
    }

    /// The grid scan of `scans` ([`scan`]), timed.
    fn timed_scan(&self, problem: &mut Problem, scans: &[(usize, usize)]) {
        if scans.is_empty() {
            return;
        }
        let (t0, s0) = (std::time::Instant::now(), problem.simulations());
        scan(problem, scans, &self.search_sim);
        self.record(
            "grid scan",
            t0.elapsed().as_secs_f64(),
            problem.simulations() - s0,
        );
    }

    /// The global search over the parameters `global` (indices in `free` and `bounds`), the
    /// others held at
    /// their start: scan (the parameters that ask for it), swarm, scan again from the swarm's
    /// best (the interacting parameters it corrected move the valleys the scanned ones lie
    /// in), the local method. Its best values, simulations and failures.
    fn search(
        &self,
        unit: &Unit,
        free: &[FreeParam],
        bounds: &[FreeBound],
        global: &[usize],
        tie_refs: &[(ParamRef, ParamRef)],
    ) -> (Vec<f64>, usize, usize) {
        let mut held_unit = unit.clone();
        for f in free {
            held_unit.set(f.r, f.start);
        }
        let mut problem = self.env.problem(
            held_unit,
            global.iter().map(|&j| free[j].clone()).collect(),
            self.env.sp.fit.clone(),
            tie_refs,
        );
        problem.cancel = self.env.opts.cancel.clone();
        let scans: Vec<(usize, usize)> = global
            .iter()
            .enumerate()
            .filter(|(_, &j)| bounds[j].scan >= 2)
            .map(|(jj, &j)| (jj, bounds[j].scan))
            .collect();
        self.timed_scan(&mut problem, &scans);
        let swarm_only = FitOptions {
            lbfgs_iterations: 0,
            ..self.fit_opts.clone()
        };
        let progress = self.env.progress;
        let (best, phases) = search(&problem, &swarm_only, self.label, progress, true, &[]);
        self.record_phases(&phases);
        for (f, v) in problem.free.iter_mut().zip(&best) {
            f.start = *v;
        }
        self.timed_scan(&mut problem, &scans);
        let (best, phases) = search(&problem, &self.fit_opts, self.label, progress, false, &[]);
        self.record_phases(&phases);
        (best, problem.simulations(), problem.failures())
    }

    /// The local method over every parameter from `x` (when some are polish-only). Its best
    /// values, simulations and failures.
    fn polish(
        &self,
        unit: &Unit,
        free: &[FreeParam],
        x: &[f64],
        tie_refs: &[(ParamRef, ParamRef)],
    ) -> (Vec<f64>, usize, usize) {
        let polish_free: Vec<FreeParam> = free
            .iter()
            .zip(x)
            .map(|(f, v)| FreeParam {
                start: *v,
                ..f.clone()
            })
            .collect();
        let env = self.env;
        let mut problem = env.problem(unit.clone(), polish_free, env.sp.fit.clone(), tie_refs);
        problem.cancel = env.opts.cancel.clone();
        let (best, phases) = search(
            &problem,
            &self.fit_opts,
            &format!("{} (polish)", self.label),
            env.progress,
            false,
            &[],
        );
        self.record_phases(&phases);
        (best, problem.simulations(), problem.failures())
    }

    /// The re-fit at `x`: the χ² of the fitted and held-out samples and the RMS of each compared
    /// channel from one accurate simulation per event (the fitted and held-out samples of a
    /// block split are windows on the same events; held-out events are simulated on their own),
    /// the priors' part, the residual's variance inflation.
    fn score(
        &self,
        unit: &Unit,
        free: Vec<FreeParam>,
        x: Vec<f64>,
        tie_refs: &[(ParamRef, ParamRef)],
        simulations: usize,
        failures: usize,
    ) -> Result<Refit, RefitError> {
        let env = self.env;
        let sp = env.sp;
        let t_acc = std::time::Instant::now();
        let fit_problem = env.problem(unit.clone(), free.clone(), sp.fit.clone(), tie_refs);
        let held = env.problem(unit.clone(), free, sp.held.clone(), tie_refs);
        let (r_fit, r_held, rms) = residuals(&fit_problem, &held, sp.blocks, env.compare, &x)
            .map_err(|e| RefitError::Simulation(e.to_string()))?;
        let chi2_prior = sum_of_squares(&fit_problem.prior_residuals(&x));
        // One accurate simulation per fitted event, and per held-out event.
        self.record(
            "χ² (accurate)",
            t_acc.elapsed().as_secs_f64(),
            sp.fit.len() + if sp.blocks { 0 } else { sp.held.len() },
        );
        let channels = match env.compare {
            Some(c) => c.weights.len().max(1),
            None if env.weights.0 > 0.0 && env.weights.1 > 0.0 => 2,
            None => 1,
        };
        Ok(Refit {
            unit: fit_problem.unit_at(&x),
            values: x,
            chi2_fit: sum_of_squares(&r_fit),
            chi2_held: sum_of_squares(&r_held),
            chi2_prior,
            n_fit: r_fit.len(),
            n_held: r_held.len(),
            simulations,
            failures,
            vif: variance_inflation(&r_fit, channels),
            rms,
        })
    }
}

/// The fitted residuals, the held-out residuals and the RMS of each compared channel.
type Residuals = (Vec<f64>, Vec<f64>, Vec<f64>);

/// The fitted and held-out residuals at `x` and the RMS of each compared channel, from one
/// accurate simulation per fitted event (`blocks`: the held-out samples are windows on the same
/// events) and one per held-out event otherwise.
fn residuals(
    fit: &Problem,
    held: &Problem,
    blocks: bool,
    compare: Option<&Compare>,
    x: &[f64],
) -> Result<Residuals, crate::problem::ProblemError> {
    let acc = accurate_integrator();
    match compare {
        None => {
            let pq = fit.simulate(x, &acc)?;
            let r_fit = fit.residuals_from(x, &pq)?;
            let r_held = if blocks {
                held.residuals_from(x, &pq)
            } else {
                held.residuals(x, &acc)
            }?;
            let (p, q) = rms_over_events(fit, blocks.then_some(held), &pq);
            Ok((r_fit, r_held, vec![p, q]))
        }
        Some(cmp) => {
            let outs = fit.simulate_outputs(x, &acc)?;
            let r_fit = fit.residuals_from_outputs(x, &outs)?;
            let r_held = if blocks {
                held.residuals_from_outputs(x, &outs)
            } else {
                held.residuals(x, &acc)
            }?;
            let rms = rms_of_channels(fit, blocks.then_some(held), &outs, cmp);
            Ok((r_fit, r_held, rms))
        }
    }
}

/// RMS of each channel of `cmp` (unweighted) over the windows of `fit`'s events, plus those of
/// `held`'s when given, from the playback-mode simulation `outs`.
fn rms_of_channels(
    fit: &Problem,
    held: Option<&Problem>,
    outs: &[itaipu_dynamics::mode::ModeOutputs],
    cmp: &Compare,
) -> Vec<f64> {
    cmp.weights
        .iter()
        .map(|&(c, _)| {
            let (mut s, mut n) = (0.0, 0usize);
            for (i, out) in outs.iter().enumerate() {
                let parts = std::iter::once(&fit.events[i]).chain(held.map(|h| &h.events[i]));
                for ev in parts {
                    let (Some(sim), Some(meas)) = (out.channel(c), ev.measured(c)) else {
                        continue;
                    };
                    for k in (0..ev.in_window.len()).filter(|&k| ev.in_window[k]) {
                        s += (sim[k] - meas[k]).powi(2);
                        n += 1;
                    }
                }
            }
            (s / n.max(1) as f64).sqrt()
        })
        .collect()
}

/// RMS of P and Q (unweighted) over the windows of `fit`'s events, plus those of `held`'s
/// (windows on the same events, in the same order) when given, from the simulation `pq`.
fn rms_over_events(fit: &Problem, held: Option<&Problem>, pq: &[SimulatedPq]) -> (f64, f64) {
    let mut s = WindowSums::default();
    for (i, (p, q)) in pq.iter().enumerate() {
        let parts = std::iter::once(&fit.events[i]).chain(held.map(|h| &h.events[i]));
        for ev in parts {
            let w = ev.window_sums(p, q);
            s.p += w.p;
            s.q += w.q;
            s.n += w.n;
        }
    }
    let n = s.n.max(1) as f64;
    ((s.p / n).sqrt(), (s.q / n).sqrt())
}

/// Standard errors of the re-fitted parameters `bounds` at `values` of `unit` (already at
/// those values), over every sample of `events`, with the priors' rows: `σ² (JᵀJ)⁻¹` by
/// [`crate::identify::analyse`]. `None` when a perturbed unit does not simulate.
pub(super) fn std_errors(
    unit: &Unit,
    bounds: &[FreeBound],
    ties: &[(String, String)],
    values: &[f64],
    events: &[Event],
    weights: (f64, f64),
    compare: Option<&Compare>,
) -> Option<Vec<f64>> {
    let free: Vec<FreeParam> = resolve(unit, bounds)
        .ok()?
        .into_iter()
        .zip(values)
        .map(|(f, v)| FreeParam { start: *v, ..f })
        .collect();
    let data: Vec<EventData> = events
        .iter()
        .map(|e| EventData::new(e, None, None))
        .collect::<Result<_, _>>()
        .ok()?;
    let problem = problem_for(
        unit.clone(),
        free,
        data,
        weights,
        compare,
        &tie_refs(unit, ties).ok()?,
    );
    let jac = crate::fit::jacobian(&problem, values)?;
    let rss = sum_of_squares(&problem.residuals(values, &accurate_integrator()).ok()?);
    Some(crate::identify::analyse(&jac, rss, crate::fit::CORRELATION_LIMIT).std_errors)
}

/// The parameters of `ties` (`(from, to)` paths) in `unit`.
pub(super) fn tie_refs(
    unit: &Unit,
    ties: &[(String, String)],
) -> Result<Vec<(ParamRef, ParamRef)>, RefitError> {
    let param = |p: &str| unit.param(p).map_err(|e| RefitError::Setup(e.to_string()));
    ties.iter()
        .map(|(a, b)| Ok((param(a)?, param(b)?)))
        .collect()
}

/// Weight of the priors' residuals in a re-fit: the re-fits' residuals are already in units of
/// the noise (weights 1/σ²), so a prior residual `ln(x/x₀)/spread` counts as one standardised
/// sample and the fitted χ² is the negative log-posterior (times 2).
pub(super) const PRIOR_WEIGHT: f64 = 1.0;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::profile::RefitKind;
    use crate::diagnose::trial::{scenario, truth_and_event};
    use crate::fit::{fitness, Silent};

    /// A re-fit's RMS comes from its own simulation over the fitted and held-out blocks: it
    /// equals the RMS of [`fitness`] over every sample of the event (a separate simulation), and
    /// the fitted blocks alone give another number.
    #[test]
    fn a_refits_rms_covers_every_sample_of_the_event() {
        let (unit, ev) = truth_and_event(&scenario("saturation", 3, None)).unwrap();
        let mut calibrated = unit.clone();
        let r = calibrated.param("exciter.k").unwrap();
        calibrated.set(r, 0.8 * unit.get(r));
        let sp =
            super::super::split::split(std::slice::from_ref(&ev), &[], 0.5, Default::default())
                .unwrap();
        let opts = DiagnoseOptions::default();
        let env = RefitEnv {
            sp: &sp,
            weights: (1.0, 1.0),
            compare: None,
            opts: &opts,
            profile: None,
            progress: &Silent,
        };
        let out = refit(
            &env,
            &calibrated,
            &[],
            &[],
            &Label::new(RefitKind::Reference, "as given"),
        )
        .unwrap();
        let (f, _) = fitness(&calibrated, &ev, false).unwrap();
        let (p, q) = (out.rms[0], out.rms[1]);
        assert!(
            (p - f.rms_p).abs() <= 1e-9 * f.rms_p,
            "{p} against {}",
            f.rms_p
        );
        assert!(
            (q - f.rms_q).abs() <= 1e-9 * f.rms_q,
            "{q} against {}",
            f.rms_q
        );
        let fitted_only = rms_over_events(
            &Problem::new(calibrated.clone(), vec![], sp.fit.clone(), (1.0, 1.0)),
            None,
            &Problem::new(calibrated, vec![], sp.fit.clone(), (1.0, 1.0))
                .simulate(&[], &accurate_integrator())
                .unwrap(),
        );
        assert!(
            (fitted_only.0 - p).abs() > 1e-6 * p,
            "the held-out blocks count"
        );
    }
}
