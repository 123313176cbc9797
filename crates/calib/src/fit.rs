//! Staged calibration: generator, then AVR, PSS, governor, each by PSO then L-BFGS (paper 000
//! Algorithm 1), with the incremental and simultaneous-first strategies of paper 001.
//!
//! Per stage: the unit keeps or loses later stages' blocks ([`crate::spec::StageBlocks`]),
//! `set` values and `replace` blocks are applied, the swarm searches the stage's box from the
//! current values, L-BFGS refines the swarm's best, and the best of start / swarm / L-BFGS by
//! an accurate re-evaluation is kept. The Gauss-Newton (Fisher) approximation at that point
//! gives standard errors and correlations. Results carry over to the next stage.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::{simulate_prepared, Traces};
use itaipu_dynamics::unit::{ParamRef, Unit};
use itaipu_dynamics::unit_file;
use rayon::prelude::*;
use serde::Serialize;

use crate::identify;
use crate::local;
use crate::problem::{
    accurate_integrator, objective_weights, search_integrator, sum_of_squares, EventData,
    FreeParam, Prior, Problem,
};
use crate::pso::{self, PsoOptions};
use crate::spec::{CalibSpec, LocalMethod, Objective, StageSpec, Strategy, Weights, STAGES};

/// Correlation above which two parameters are reported as not separately identifiable.
pub const CORRELATION_LIMIT: f64 = 0.95;
/// Relative standard error above which a parameter is reported as only weakly determined.
pub const WEAK_LIMIT: f64 = 0.01;

/// Receives progress (implemented by the CLI as a progress bar or plain lines).
pub trait Progress: Sync {
    /// A phase starts: `stage`, `phase` ("pso", "lbfgs", …), expected iterations.
    fn phase(&self, stage: &str, phase: &str, total: u64);
    /// An iteration of the current phase finished with this best objective.
    fn iteration(&self, i: u64, best: f64);
    /// A line of information.
    fn message(&self, text: &str);
}

/// A [`Progress`] that says nothing.
pub struct Silent;

impl Progress for Silent {
    fn phase(&self, _: &str, _: &str, _: u64) {}
    fn iteration(&self, _: u64, _: f64) {}
    fn message(&self, _: &str) {}
}

/// Options of a fit beyond the spec.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Stages to run, in order (subset of gen, avr, pss, tg).
    pub stages: Vec<String>,
    pub strategy: Strategy,
    pub seed: u64,
    pub particles: usize,
    pub pso_iterations: usize,
    pub lbfgs_iterations: u64,
    pub lbfgs_memory: usize,
    /// Largest RK4 step of the L-BFGS phase [s] ([`local::RK4_STEP_MAX_S`] in a calibration).
    pub lbfgs_step_max_s: f64,
    /// After several stages, search every freed parameter together on the full unit (swarm
    /// from the staged result, then the local method from the swarm's best, the staged result
    /// and the datasheet values; objective P+Q), reported as the stage `joint`.
    pub polish: bool,
    /// The local method after each swarm.
    pub local: LocalMethod,
}

impl FitOptions {
    /// Options from a spec, running every stage it lists.
    pub fn from_spec(spec: &CalibSpec) -> Self {
        Self {
            stages: spec.stages.iter().map(|s| s.name.clone()).collect(),
            strategy: spec.strategy,
            seed: spec.seed,
            particles: spec.pso.particles,
            pso_iterations: spec.pso.iterations,
            lbfgs_iterations: spec.lbfgs.iterations,
            lbfgs_memory: spec.lbfgs.memory,
            lbfgs_step_max_s: local::RK4_STEP_MAX_S,
            polish: spec.polish,
            local: spec.local,
        }
    }
}

/// Why a fit could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The spec does not fit the unit (unknown parameter, bad replacement block…).
    #[error("calibration spec: {0}")]
    Spec(String),
    #[error("stage {stage}: {msg}")]
    Stage { stage: String, msg: String },
    #[error("{0}")]
    Setup(String),
    /// Stopped by [`FitControl::cancel`] at a candidate boundary; `finished` names the passes
    /// (stages) that completed and were handed to [`FitControl::on_stage`].
    #[error("interrupted; finished stages: {}", if finished.is_empty() { "none".to_string() } else { finished.join(", ") })]
    Interrupted { finished: Vec<String> },
    /// [`FitControl::on_stage`] failed (e.g. a stage's outputs could not be written).
    #[error("{0}")]
    Output(String),
}

impl FitError {
    /// Short stable identifier of the variant (`"spec"`, `"stage"`, `"setup"`).
    pub fn kind(&self) -> &'static str {
        match self {
            FitError::Spec(_) => "spec",
            FitError::Stage { .. } => "stage",
            FitError::Setup(_) => "setup",
            FitError::Interrupted { .. } => "interrupted",
            FitError::Output(_) => "output",
        }
    }
}

/// One parameter's line in a stage report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamReport {
    pub param: String,
    pub unit: String,
    pub start: f64,
    pub min: f64,
    pub max: f64,
    pub result: f64,
    /// Standard error from the Fisher approximation (∞ when not determined by the data).
    pub std_error: f64,
    pub at_bound: bool,
    pub log_scaled: bool,
}

/// Objective values of the unit on one event.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventFitness {
    pub event: String,
    /// Σ(ΔP² + ΔQ²) over the event's fit window (system base), RaPId's J.
    pub j_pq: f64,
    pub rms_p: f64,
    pub rms_q: f64,
    pub samples: usize,
    pub held_out: bool,
}

/// One phase's counters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PhaseReport {
    pub phase: String,
    pub iterations: u64,
    pub best_objective: f64,
    pub stopped_by: String,
}

/// The report of one stage.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageReport {
    pub stage: String,
    pub strategy: String,
    pub objective: Objective,
    pub weights: Weights,
    pub window: Option<[f64; 2]>,
    pub lowpass_hz: Option<f64>,
    pub models: Vec<String>,
    pub parameters: Vec<ParamReport>,
    /// Stage objective before and after (accurate integrator): the weighted sum of squares plus
    /// the datasheet prior's term.
    pub objective_before: f64,
    pub objective_after: f64,
    /// The prior's term in `objective_before` and `objective_after` (0 without a prior).
    pub prior_before: f64,
    pub prior_after: f64,
    /// P+Q fitness per event after the stage (fit and held-out events).
    pub fitness: Vec<EventFitness>,
    pub phases: Vec<PhaseReport>,
    pub simulations: usize,
    pub failed_candidates: usize,
    pub failure_messages: Vec<String>,
    pub wall_s: f64,
    pub seed: u64,
    pub residual_variance: f64,
    pub correlation: Vec<Vec<f64>>,
    /// Pairs with |ρ| above [`CORRELATION_LIMIT`]: not separately identifiable.
    pub correlated_pairs: Vec<(String, String, f64)>,
    pub unidentified: Vec<String>,
    /// Determined, but with a relative standard error above [`WEAK_LIMIT`].
    pub weakly_determined: Vec<String>,
    /// Parameters the data determine: not unidentified, not in a correlated pair, relative
    /// standard error at most [`WEAK_LIMIT`].
    pub identifiable: Vec<String>,
    pub condition_number: f64,
}

/// The whole fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitReport {
    pub unit: String,
    pub events: Vec<String>,
    pub held_out: Vec<String>,
    pub strategy: String,
    pub seed: u64,
    pub threads: usize,
    /// P+Q fitness of the starting unit (the row before any stage).
    pub start_fitness: Vec<EventFitness>,
    pub stages: Vec<StageReport>,
    pub wall_s: f64,
}

impl FitReport {
    /// The report as text: per stage its phases, the parameter table (start, bounds, result,
    /// standard error, at-bound flag), what the data do not determine, then the fitness table
    /// per event. What `itaipu-calib fit` prints and `FitResult.fit_report()` returns.
    pub fn to_text(&self) -> String {
        use std::fmt::Write;
        let r = self;
        let mut out = String::new();
        for s in &r.stages {
            let _ = writeln!(out);
            let _ = writeln!(
                out,
                "stage {} ({}, objective {:?}): {:.5} -> {:.5}; {} simulations, \
                 {} failed candidates, {:.1} s",
                s.stage,
                s.strategy,
                s.objective,
                s.objective_before,
                s.objective_after,
                s.simulations,
                s.failed_candidates,
                s.wall_s
            );
            for ph in &s.phases {
                let _ = writeln!(
                    out,
                    "  {:<28} {:>4} iterations, best {:.5} ({})",
                    ph.phase, ph.iterations, ph.best_objective, ph.stopped_by
                );
            }
            let _ = writeln!(
                out,
                "  {:<22} {:>10} {:>21} {:>10} {:>10}",
                "parameter", "start", "bounds", "result", "std err"
            );
            for p in &s.parameters {
                let _ = writeln!(
                    out,
                    "  {:<22} {:>10.4} {:>10}-{:<10} {:>10.4} {:>10.2e}{}",
                    p.param,
                    p.start,
                    format!("{}", p.min),
                    format!("{}", p.max),
                    p.result,
                    p.std_error,
                    if p.at_bound { "  at bound" } else { "" }
                );
            }
            for (a, b, rho) in &s.correlated_pairs {
                let _ = writeln!(
                    out,
                    "  not separately identifiable: {a} and {b} (correlation {rho:+.3})"
                );
            }
            for u in &s.unidentified {
                let _ = writeln!(out, "  not determined by the data: {u}");
            }
            if !s.weakly_determined.is_empty() {
                let _ = writeln!(
                    out,
                    "  weakly determined (std err > 1 %): {}",
                    s.weakly_determined.join(", ")
                );
            }
            let _ = writeln!(
                out,
                "  identifiable: {}",
                if s.identifiable.is_empty() {
                    "none".to_string()
                } else {
                    s.identifiable.join(", ")
                }
            );
        }
        let _ = writeln!(out);
        let _ = writeln!(
            out,
            "fitness J = sum(dP^2 + dQ^2) per event (system base; * = held out)"
        );
        let mut header = vec!["stage".to_string()];
        header.extend(
            r.start_fitness
                .iter()
                .map(|f| format!("{}{}", f.event, if f.held_out { "*" } else { "" })),
        );
        let _ = writeln!(
            out,
            "  {}",
            header
                .iter()
                .map(|h| format!("{h:>22}"))
                .collect::<String>()
        );
        let row = |out: &mut String, name: &str, f: &[EventFitness]| {
            let _ = writeln!(
                out,
                "  {:>22}{}",
                name,
                f.iter()
                    .map(|x| format!("{:>22.4}", x.j_pq))
                    .collect::<String>()
            );
        };
        row(&mut out, "start", &r.start_fitness);
        for s in &r.stages {
            row(&mut out, &s.stage, &s.fitness);
        }
        let _ = writeln!(out, "total {:.1} s on {} threads", r.wall_s, r.threads);
        out
    }
}

/// A stage's units and traces (not serialised).
pub struct StageOutput {
    pub stage: String,
    pub start_unit: Unit,
    pub calibrated_unit: Unit,
    /// Per fit event: traces of the start and the calibrated stage unit.
    pub traces: Vec<(String, Traces, Traces)>,
}

/// Everything a fit returns.
pub struct FitResult {
    pub report: FitReport,
    /// The calibrated full unit (every block, with the stages' results).
    pub unit: Unit,
    pub stages: Vec<StageOutput>,
}

/// What a pass hands out as it finishes: its report, its units and traces, and the full unit
/// (every stage's results so far) that the next pass starts from.
pub type OnStage<'a> = dyn Fn(&StageReport, &StageOutput, &Unit) -> Result<(), String> + Sync + 'a;

/// Passes finished by an earlier, interrupted run, to go on from.
#[derive(Clone)]
pub struct Resume {
    /// Labels of the finished passes, in order (a prefix of the passes this run would make).
    pub finished: Vec<String>,
    /// The full unit after the last finished pass (what [`FitControl::on_stage`] was given).
    pub master: Unit,
}

/// Control of a running fit beyond its options.
#[derive(Default)]
pub struct FitControl<'a> {
    /// When set (by a signal handler, say), every later candidate evaluation fails at once;
    /// the pass under way is dropped and the fit returns [`FitError::Interrupted`].
    pub cancel: Option<Arc<AtomicBool>>,
    /// Called after every finished pass, before the next starts.
    pub on_stage: Option<&'a OnStage<'a>>,
    /// Go on after these finished passes instead of running them again. Every pass depends
    /// only on the unit it starts from and the options (the swarm's seed is per pass), so the
    /// numbers are those of an uninterrupted run.
    pub resume: Option<Resume>,
}

impl FitControl<'_> {
    fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

/// The labels of the passes `fit` makes with `opts`, in order (`simultaneous`, the stages,
/// `joint`).
pub fn pass_labels(opts: &FitOptions) -> Vec<String> {
    let mut v = vec![];
    if opts.strategy == Strategy::SimultaneousFirst {
        v.push("simultaneous".to_string());
    }
    v.extend(opts.stages.iter().cloned());
    if opts.polish && opts.stages.len() > 1 {
        v.push("joint".to_string());
    }
    v
}

/// P+Q fitness of `unit` on `event` (accurate integrator); `None` if it fails.
pub fn fitness(
    unit: &Unit,
    event: &Event,
    held_out: bool,
) -> Result<(EventFitness, Traces), String> {
    let data = EventData::new(event, None, None)?;
    let mut u = unit.clone();
    let tr = simulate_prepared(&mut u, &data.prepared, event, &accurate_integrator())
        .map_err(|e| e.to_string())?;
    let (p, q) = (tr.get("p_pu").unwrap(), tr.get("q_pu").unwrap());
    let (mut sp, mut sq, mut n) = (0.0, 0.0, 0usize);
    for k in 0..p.len() {
        if data.in_window[k] {
            sp += (p[k] - data.p_meas[k]).powi(2);
            sq += (q[k] - data.q_meas[k]).powi(2);
            n += 1;
        }
    }
    let nn = n.max(1) as f64;
    Ok((
        EventFitness {
            event: event.name.clone(),
            j_pq: sp + sq,
            rms_p: (sp / nn).sqrt(),
            rms_q: (sq / nn).sqrt(),
            samples: n,
            held_out,
        },
        tr,
    ))
}

fn stage_err(stage: &str, msg: impl Into<String>) -> FitError {
    FitError::Stage {
        stage: stage.to_string(),
        msg: msg.into(),
    }
}

/// Applies a stage's `set` and `replace` entries to the master unit.
fn apply_stage_edits(master: &mut Unit, spec: &StageSpec) -> Result<(), FitError> {
    for (section, table) in &spec.replace {
        let block = build_block(section, table).map_err(|m| stage_err(&spec.name, m))?;
        master
            .put(section, block, &[])
            .map_err(|e| stage_err(&spec.name, e.to_string()))?;
    }
    for (path, v) in &spec.set {
        let r = master
            .param(path)
            .map_err(|e| stage_err(&spec.name, format!("set: {e}")))?;
        master.set(r, *v);
    }
    Ok(())
}

/// Builds a replacement block from a unit-file table (the unit-file parser's own function): a
/// registry model or a user-defined diagram (`model = "diagram"`, inline `diagram` table or a
/// file relative to the working directory).
fn build_block(
    section: &str,
    table: &toml::Table,
) -> Result<Box<dyn itaipu_dynamics::block::Block>, String> {
    let (block, _) = unit_file::build_any_block(
        &format!("replace.{section}"),
        table,
        std::path::Path::new("."),
    )?;
    Ok(block)
}

/// A stage spec combining the free parameters of `stages` (for the simultaneous and joint
/// passes), objective P+Q.
fn combined_stage(name: &str, spec: &CalibSpec, stages: &[String]) -> StageSpec {
    let mut all = StageSpec {
        name: name.into(),
        objective: Objective::Pq,
        weights: Weights::default(),
        window: None,
        lowpass_hz: None,
        set: Default::default(),
        free: vec![],
        tie: Default::default(),
        replace: Default::default(),
    };
    for s in stages {
        let st = spec.stage(s).expect("stages are checked against the spec");
        all.free.extend(st.free.iter().cloned());
        all.tie
            .extend(st.tie.iter().map(|(a, b)| (a.clone(), b.clone())));
        all.window = all.window.or(st.window);
        all.lowpass_hz = all.lowpass_hz.or(st.lowpass_hz);
    }
    all
}

/// Resolves a stage's free parameters in `unit`, each with its prior around its value in
/// `datasheet` (the unit before the fit) with the parameter's spread or `default_spread`.
fn free_params(
    unit: &Unit,
    spec: &StageSpec,
    datasheet: &Unit,
    default_spread: f64,
) -> Result<Vec<FreeParam>, FitError> {
    spec.free
        .iter()
        .map(|f| {
            let r = unit.param(&f.param).map_err(|e| {
                stage_err(
                    &spec.name,
                    format!(
                        "free parameter {}: {e} (is its block part of this stage?)",
                        f.param
                    ),
                )
            })?;
            let start = f.start.unwrap_or(unit.get(r));
            let spread = f.spread.unwrap_or(default_spread);
            let prior = datasheet
                .param(&f.param)
                .ok()
                .map(|d| Prior {
                    center: datasheet.get(d),
                    spread,
                })
                .filter(|p| p.spread > 0.0 && p.center > 0.0);
            Ok(FreeParam::new(
                unit.param_path(r),
                r,
                f.min,
                f.max,
                start,
                unit.param_spec(r).unit,
            )
            .with_prior(prior))
        })
        .collect()
}

/// Resolves a stage's ties `to = from` in `unit` as `(from, to)` references.
fn resolve_ties(unit: &Unit, spec: &StageSpec) -> Result<Vec<(ParamRef, ParamRef)>, FitError> {
    spec.tie
        .iter()
        .map(|(to, from)| {
            let r = |p: &str| {
                unit.param(p)
                    .map_err(|e| stage_err(&spec.name, format!("tie {to} = {from}: {e}")))
            };
            Ok((r(from)?, r(to)?))
        })
        .collect()
}

/// Gives every tied parameter of `spec` its source's value in `unit`.
fn apply_ties(unit: &mut Unit, spec: &StageSpec) -> Result<(), FitError> {
    for (from, to) in resolve_ties(unit, spec)? {
        let v = unit.get(from);
        unit.set(to, v);
    }
    Ok(())
}

/// Runs the swarm then L-BFGS on `problem` from its start; returns the best physical values,
/// the phase reports, and the objective at the best (accurate integrator).
///
/// The local phase also runs from each point of `also_from` (physical values): the joint pass
/// starts from the staged result and from the datasheet values, so that a stage that derailed
/// (fitted a unit whose other blocks were still wrong) cannot trap the result.
pub(crate) fn search(
    problem: &Problem,
    opts: &FitOptions,
    stage: &str,
    progress: &dyn Progress,
    use_pso: bool,
    also_from: &[Vec<f64>],
) -> (Vec<f64>, Vec<PhaseReport>) {
    let n = problem.dim();
    let start = problem.start();
    let mut phases = vec![];
    let mut candidates = vec![start.clone()];
    if use_pso && n > 0 && opts.pso_iterations > 0 {
        progress.phase(stage, "pso", opts.pso_iterations as u64);
        let sim = search_integrator();
        let pso_opts = PsoOptions {
            particles: opts.particles,
            iterations: opts.pso_iterations,
            seed: opts.seed,
            stall_iterations: 30,
            ..Default::default()
        };
        let u0 = problem.to_unit(&start);
        let res = pso::minimize(
            |u: &[f64]| problem.cost(&problem.from_unit(u), &sim),
            n,
            Some(&u0),
            &pso_opts,
            |i, best| progress.iteration(i as u64, best),
        );
        phases.push(PhaseReport {
            phase: "pso".into(),
            iterations: res.iterations as u64,
            best_objective: res.best_cost,
            stopped_by: format!("{:?}", res.stopped_by),
        });
        candidates.push(problem.from_unit(&res.best));
    }
    let from = candidates.last().cloned().unwrap_or_default();
    let lm = opts.local == LocalMethod::Lm;
    let starts: Vec<Vec<f64>> = std::iter::once(from)
        .chain(also_from.iter().cloned())
        .collect();
    for (i, from) in starts.iter().enumerate() {
        if n == 0 || opts.lbfgs_iterations == 0 {
            break;
        }
        let name = if lm { "levenberg-marquardt" } else { "lbfgs" };
        progress.phase(stage, name, opts.lbfgs_iterations);
        let res = if lm {
            local::levenberg_marquardt(problem, from, opts.lbfgs_iterations)
        } else {
            local::refine(
                problem,
                from,
                opts.lbfgs_iterations,
                opts.lbfgs_memory,
                opts.lbfgs_step_max_s,
            )
        };
        progress.iteration(res.iterations, res.best_cost);
        let from_txt = if i == 0 {
            String::new()
        } else {
            format!(" from start {}", i + 1)
        };
        phases.push(PhaseReport {
            phase: if lm {
                format!("{name}{from_txt} (Dormand-Prince, rtol 1e-8)")
            } else {
                format!("{name}{from_txt} (RK4 h = {:.3} ms)", res.step_s * 1e3)
            },
            iterations: res.iterations,
            best_objective: res.best_cost,
            stopped_by: res.stopped_by.clone(),
        });
        if i > 0 {
            // The first start (the swarm's best or the stage start) is a candidate already.
            candidates.push(from.clone());
        }
        candidates.push(res.best);
    }
    // Keep the best candidate by an accurate evaluation (the phases used different integrators).
    let acc = accurate_integrator();
    let (_, k) = problem.best_of(&candidates, &acc);
    (candidates[k].clone(), phases)
}

/// Jacobian of the residuals in physical units (accurate integrator): central differences,
/// one-sided where a parameter sits on a bound (the model may reject values beyond it, e.g. a
/// negative damping).
pub(crate) fn jacobian(problem: &Problem, x: &[f64]) -> Option<Vec<Vec<f64>>> {
    let acc = accurate_integrator();
    let r0 = problem.residuals(x, &acc).ok()?;
    let cols: Vec<Option<Vec<f64>>> = (0..x.len())
        .into_par_iter()
        .map(|j| {
            let f = &problem.free[j];
            let h = 1e-4 * (f.hi - f.lo).min(x[j].abs().max(1e-3 * (f.hi - f.lo)));
            let at = |v: f64| {
                let mut xv = x.to_vec();
                xv[j] = v;
                problem.residuals(&xv, &acc).ok()
            };
            let (plus, minus, span) = if x[j] - h < f.lo {
                (at(x[j] + h)?, r0.clone(), h)
            } else if x[j] + h > f.hi {
                (r0.clone(), at(x[j] - h)?, h)
            } else {
                (at(x[j] + h)?, at(x[j] - h)?, 2.0 * h)
            };
            Some(
                plus.iter()
                    .zip(&minus)
                    .map(|(a, b)| (a - b) / span)
                    .collect(),
            )
        })
        .collect();
    let cols: Vec<Vec<f64>> = cols.into_iter().collect::<Option<_>>()?;
    let rows = cols.first().map_or(0, |c| c.len());
    Some(
        (0..rows)
            .map(|k| cols.iter().map(|c| c[k]).collect())
            .collect(),
    )
}

/// Identifiability results in parameter names.
struct Ident {
    std_errors: Vec<f64>,
    correlation: Vec<Vec<f64>>,
    pairs: Vec<(String, String, f64)>,
    unidentified: Vec<String>,
    sigma2: f64,
    condition: f64,
}

/// Runs a stage (or the simultaneous pass) on `unit` with `free` parameters.
#[allow(clippy::too_many_arguments)]
fn run_stage(
    name: &str,
    label: &str,
    unit: Unit,
    free: Vec<FreeParam>,
    spec: &StageSpec,
    events: &[Event],
    held_out: &[Event],
    opts: &FitOptions,
    progress: &dyn Progress,
    use_pso: bool,
    also_from: &[Vec<f64>],
    cancel: Option<Arc<AtomicBool>>,
) -> Result<(StageReport, StageOutput, Vec<f64>), FitError> {
    let t0 = Instant::now();
    let data: Vec<EventData> = events
        .iter()
        .map(|e| EventData::new(e, spec.window, spec.lowpass_hz))
        .collect::<Result<_, _>>()
        .map_err(|m| stage_err(name, m))?;
    let weights = objective_weights(spec.objective, spec.weights);
    let ties = resolve_ties(&unit, spec)?;
    let mut problem = Problem::new(unit, free, data, weights);
    problem.ties = ties;
    problem.cancel = cancel;
    if problem.free.iter().any(|f| f.prior.is_some()) {
        problem.prior_weight = problem.measured_noise_variance();
    }
    let acc = accurate_integrator();
    let start = problem.start();
    let objective_before = problem
        .residuals(&start, &acc)
        .map(|r| sum_of_squares(&r))
        .map_err(|m| stage_err(name, format!("the starting unit does not simulate: {m}")))?;
    let mut phases = vec![];
    let best = if opts.strategy == Strategy::Incremental && name == "gen" {
        // Free the parameters one at a time in the listed order, each step from the last.
        let mut x = start.clone();
        for i in 1..=problem.dim() {
            let mut sub = Problem::new(
                problem.unit_at(&x),
                problem.free[..i]
                    .iter()
                    .zip(&x)
                    .map(|(f, v)| FreeParam {
                        start: *v,
                        ..f.clone()
                    })
                    .collect(),
                problem.events.clone(),
                weights,
            );
            sub.penalty = problem.penalty;
            sub.ties = problem.ties.clone();
            sub.prior_weight = problem.prior_weight;
            sub.cancel = problem.cancel.clone();
            let (b, ph) = search(
                &sub,
                opts,
                &format!("{label} {i}/{}", problem.dim()),
                progress,
                false,
                &[],
            );
            x[..i].copy_from_slice(&b);
            phases.extend(ph.into_iter().map(|p| PhaseReport {
                phase: format!("step {i} ({}): {}", problem.free[i - 1].path, p.phase),
                ..p
            }));
        }
        x
    } else {
        let (b, ph) = search(&problem, opts, label, progress, use_pso, also_from);
        phases = ph;
        b
    };
    let r_best = problem
        .residuals(&best, &acc)
        .map_err(|m| stage_err(name, format!("the calibrated unit does not simulate: {m}")))?;
    let objective_after = sum_of_squares(&r_best);
    progress.message(&format!(
        "{label}: objective {objective_before:.5} -> {objective_after:.5}"
    ));

    // Identifiability at the optimum.
    let ident = jacobian(&problem, &best)
        .map(|j| identify::analyse(&j, objective_after, CORRELATION_LIMIT));
    let n = problem.dim();
    let id = match &ident {
        Some(id) => Ident {
            std_errors: id.std_errors.clone(),
            correlation: id.correlation.clone(),
            pairs: id
                .correlated_pairs
                .iter()
                .map(|&(i, j, r)| {
                    (
                        problem.free[i].path.clone(),
                        problem.free[j].path.clone(),
                        r,
                    )
                })
                .collect(),
            unidentified: id
                .unidentified
                .iter()
                .map(|&i| problem.free[i].path.clone())
                .collect(),
            sigma2: id.sigma2,
            condition: id.condition,
        },
        None => Ident {
            std_errors: vec![f64::NAN; n],
            correlation: vec![vec![f64::NAN; n]; n],
            pairs: vec![],
            unidentified: vec![],
            sigma2: f64::NAN,
            condition: f64::NAN,
        },
    };
    let Ident {
        std_errors,
        correlation,
        pairs,
        unidentified,
        sigma2,
        condition: cond,
    } = id;
    let parameters = problem
        .free
        .iter()
        .enumerate()
        .map(|(i, f)| ParamReport {
            param: f.path.clone(),
            unit: f.unit.to_string(),
            start: f.start,
            min: f.lo,
            max: f.hi,
            result: best[i],
            std_error: std_errors[i],
            at_bound: f.at_bound(best[i]),
            log_scaled: f.log,
        })
        .collect();

    let start_unit = problem.unit_at(&start);
    let calibrated_unit = problem.unit_at(&best);
    let mut fitness_rows = vec![];
    let mut traces = vec![];
    for e in events {
        let (fs, tr_end) = fitness(&calibrated_unit, e, false).map_err(|m| stage_err(name, m))?;
        let (_, tr_start) = fitness(&start_unit, e, false).map_err(|m| stage_err(name, m))?;
        fitness_rows.push(fs);
        traces.push((e.name.clone(), tr_start, tr_end));
    }
    for e in held_out {
        // A held-out event that the calibrated unit cannot simulate is reported, not fatal.
        match fitness(&calibrated_unit, e, true) {
            Ok((fs, _)) => fitness_rows.push(fs),
            Err(m) => progress.message(&format!("{label}: held-out event {}: {m}", e.name)),
        }
    }
    let flagged = |p: &String| {
        unidentified.contains(p)
            || pairs
                .iter()
                .any(|(a, b, _): &(String, String, f64)| a == p || b == p)
    };
    let rel_se = |i: usize| std_errors[i] / best[i].abs().max(1e-12);
    let weakly_determined: Vec<String> = problem
        .free
        .iter()
        .enumerate()
        .filter(|(i, f)| !flagged(&f.path) && !(rel_se(*i) <= WEAK_LIMIT))
        .map(|(_, f)| f.path.clone())
        .collect();
    let identifiable: Vec<String> = problem
        .free
        .iter()
        .filter(|f| !flagged(&f.path) && !weakly_determined.contains(&f.path))
        .map(|f| f.path.clone())
        .collect();
    let report = StageReport {
        stage: label.to_string(),
        strategy: opts.strategy.to_string(),
        objective: spec.objective,
        weights: spec.weights,
        window: spec.window,
        lowpass_hz: spec.lowpass_hz,
        models: problem
            .unit
            .instances()
            .iter()
            .map(|i| format!("{}={}", i.name, i.block.model()))
            .collect(),
        parameters,
        objective_before,
        objective_after,
        prior_before: sum_of_squares(&problem.prior_residuals(&start)),
        prior_after: sum_of_squares(&problem.prior_residuals(&best)),
        fitness: fitness_rows,
        phases,
        simulations: problem.simulations(),
        failed_candidates: problem.failures(),
        failure_messages: problem.failure_messages(),
        wall_s: t0.elapsed().as_secs_f64(),
        seed: opts.seed,
        residual_variance: sigma2,
        correlation,
        correlated_pairs: pairs,
        unidentified,
        weakly_determined,
        identifiable,
        condition_number: cond,
    };
    Ok((
        report,
        StageOutput {
            stage: label.to_string(),
            start_unit,
            calibrated_unit,
            traces,
        },
        best,
    ))
}

/// Checks, before any simulation, that every `set`, `replace` and `free` entry of the stages to
/// run resolves in the unit (as the stage will see it) and that the unit initialises.
pub fn check_spec(unit: &Unit, spec: &CalibSpec, stages: &[String]) -> Result<(), FitError> {
    let mut u = unit.clone();
    for s in stages {
        let st = spec
            .stage(s)
            .ok_or_else(|| FitError::Spec(format!("stage '{s}' is not in the spec")))?;
        apply_stage_edits(&mut u, st).map_err(|e| FitError::Spec(e.to_string()))?;
        resolve_ties(&u, st).map_err(|e| FitError::Spec(e.to_string()))?;
        let stage_unit = u
            .without(spec.removed_blocks(s))
            .map_err(|e| FitError::Spec(format!("stage {s}: {e}")))?;
        for f in &st.free {
            stage_unit.param(&f.param).map_err(|e| {
                FitError::Spec(format!(
                    "stage {s}: free parameter {}: {e} (is its block part of this stage?)",
                    f.param
                ))
            })?;
        }
    }
    Ok(())
}

/// Calibrates `unit` against `events` following `spec` (stages in `opts.stages`).
pub fn fit(
    unit: &Unit,
    spec: &CalibSpec,
    events: &[Event],
    held_out: &[Event],
    opts: &FitOptions,
    progress: &dyn Progress,
) -> Result<FitResult, FitError> {
    fit_with(
        unit,
        spec,
        events,
        held_out,
        opts,
        progress,
        &FitControl::default(),
    )
}

/// [`fit`] with an interrupt flag, a hook called after every finished pass, and a resume from
/// the passes of an interrupted run ([`FitControl`]). On resume the returned report and
/// outputs hold only the passes run now.
pub fn fit_with(
    unit: &Unit,
    spec: &CalibSpec,
    events: &[Event],
    held_out: &[Event],
    opts: &FitOptions,
    progress: &dyn Progress,
    control: &FitControl<'_>,
) -> Result<FitResult, FitError> {
    let t0 = Instant::now();
    if events.is_empty() {
        return Err(FitError::Setup("no event to fit".into()));
    }
    for s in &opts.stages {
        if !STAGES.contains(&s.as_str()) {
            return Err(FitError::Setup(format!(
                "unknown stage '{s}' (gen, avr, pss, tg)"
            )));
        }
        if spec.stage(s).is_none() {
            return Err(FitError::Setup(format!(
                "stage '{s}' is not in the calibration spec"
            )));
        }
    }
    check_spec(unit, spec, &opts.stages)?;
    let labels = pass_labels(opts);
    let skip = match &control.resume {
        None => 0,
        Some(r) => {
            if r.finished.len() > labels.len() || r.finished[..] != labels[..r.finished.len()] {
                return Err(FitError::Setup(format!(
                    "cannot resume: the finished stages ({}) are not the first passes of this fit ({}); give the same stages, strategy and options as the interrupted run",
                    r.finished.join(", "),
                    labels.join(", ")
                )));
            }
            r.finished.len()
        }
    };
    let mut master = unit.clone();
    let mut start_fitness = vec![];
    for e in events {
        start_fitness.push(
            fitness(&master, e, false)
                .map_err(|m| FitError::Setup(format!("the starting unit: {m}")))?
                .0,
        );
    }
    for e in held_out {
        if let Ok((f, _)) = fitness(&master, e, true) {
            start_fitness.push(f);
        }
    }
    if let Some(r) = &control.resume {
        if skip > 0 {
            master = r.master.clone();
        }
    }
    let mut reports = vec![];
    let mut outputs = vec![];
    let mut finished: Vec<String> = labels[..skip].to_vec();
    let mut pass = 0usize;
    let cancel = control.cancel.clone();
    // Runs before each pass: skips it when resumed past it, stops when interrupted.
    let before = |pass: usize, finished: &Vec<String>| -> Result<bool, FitError> {
        if control.cancelled() {
            return Err(FitError::Interrupted {
                finished: finished.clone(),
            });
        }
        Ok(pass >= skip)
    };
    // Runs after each pass: drops it when interrupted, hands it out otherwise.
    let after = |res: Result<(StageReport, StageOutput, Vec<f64>), FitError>,
                 finished: &Vec<String>|
     -> Result<(StageReport, StageOutput, Vec<f64>), FitError> {
        if control.cancelled() {
            return Err(FitError::Interrupted {
                finished: finished.clone(),
            });
        }
        res
    };
    let hand_out = |rep: &StageReport, out: &StageOutput, master: &Unit| -> Result<(), FitError> {
        match control.on_stage {
            Some(f) => f(rep, out, master).map_err(FitError::Output),
            None => Ok(()),
        }
    };

    if opts.strategy == Strategy::SimultaneousFirst {
        if before(pass, &finished)? {
            // All listed stages' parameters at once on the full unit, objective P+Q.
            let mut full = master.clone();
            for s in &opts.stages {
                apply_stage_edits(&mut full, spec.stage(s).expect("checked"))?;
            }
            let all = combined_stage("all", spec, &opts.stages);
            let free = free_params(&full, &all, unit, spec.prior)?;
            let res = run_stage(
                "all",
                "simultaneous",
                full.clone(),
                free.clone(),
                &all,
                events,
                held_out,
                opts,
                progress,
                true,
                &[],
                cancel.clone(),
            );
            let (rep, out, best) = after(res, &finished)?;
            // The full unit (with every stage's replacements) carries on with the joint result.
            master = full;
            for (f, v) in free.iter().zip(&best) {
                master.set(f.r, *v);
            }
            apply_ties(&mut master, &all)?;
            hand_out(&rep, &out, &master)?;
            finished.push(rep.stage.clone());
            reports.push(rep);
            outputs.push(out);
        }
        pass += 1;
    }

    for s in &opts.stages {
        if !before(pass, &finished)? {
            pass += 1;
            continue;
        }
        pass += 1;
        let st = spec.stage(s).expect("checked");
        apply_stage_edits(&mut master, st)?;
        let stage_unit = master
            .without(spec.removed_blocks(s))
            .map_err(|e| stage_err(s, e.to_string()))?;
        let free = free_params(&stage_unit, st, unit, spec.prior)?;
        let res = run_stage(
            s,
            s,
            stage_unit,
            free.clone(),
            st,
            events,
            held_out,
            opts,
            progress,
            true,
            &[],
            cancel.clone(),
        );
        let (rep, out, best) = after(res, &finished)?;
        for (f, v) in free.iter().zip(&best) {
            let r = master
                .param(&f.path)
                .map_err(|e| stage_err(s, e.to_string()))?;
            master.set(r, *v);
        }
        apply_ties(&mut master, st)?;
        hand_out(&rep, &out, &master)?;
        finished.push(rep.stage.clone());
        reports.push(rep);
        outputs.push(out);
    }

    if opts.polish && opts.stages.len() > 1 && before(pass, &finished)? {
        // Joint refinement of everything the stages freed, on the full unit.
        let mut joint = combined_stage("joint", spec, &opts.stages);
        joint.lowpass_hz = None;
        let full = master.clone();
        let free = free_params(&full, &joint, unit, spec.prior)?;
        // Start from the current values, not the spec's starting values.
        let free: Vec<FreeParam> = free
            .into_iter()
            .map(|f| FreeParam {
                start: full.get(f.r).clamp(f.lo, f.hi),
                ..f
            })
            .collect();
        // A second start at the datasheet values (the prior's centre where there is one), in
        // case the staged result lies in another, worse basin.
        let datasheet: Vec<f64> = free
            .iter()
            .map(|f| f.prior.map_or(f.start, |p| p.center).clamp(f.lo, f.hi))
            .collect();
        let res = run_stage(
            "joint",
            "joint",
            full,
            free.clone(),
            &joint,
            events,
            held_out,
            opts,
            progress,
            true,
            &[datasheet],
            cancel.clone(),
        );
        let (rep, out, best) = after(res, &finished)?;
        for (f, v) in free.iter().zip(&best) {
            master.set(f.r, *v);
        }
        apply_ties(&mut master, &joint)?;
        hand_out(&rep, &out, &master)?;
        reports.push(rep);
        outputs.push(out);
    }

    let report = FitReport {
        unit: unit.name.clone(),
        events: events.iter().map(|e| e.name.clone()).collect(),
        held_out: held_out.iter().map(|e| e.name.clone()).collect(),
        strategy: opts.strategy.to_string(),
        seed: opts.seed,
        threads: rayon::current_num_threads(),
        start_fitness,
        stages: reports,
        wall_s: t0.elapsed().as_secs_f64(),
    };
    Ok(FitResult {
        report,
        unit: master,
        stages: outputs,
    })
}

/// Search options used by tests and benchmarks that want a quick, reproducible fit.
pub fn quick_options(stages: &[&str], seed: u64) -> FitOptions {
    FitOptions {
        stages: stages.iter().map(|s| s.to_string()).collect(),
        strategy: Strategy::Sequential,
        seed,
        particles: 24,
        pso_iterations: 30,
        lbfgs_iterations: 30,
        lbfgs_memory: 7,
        lbfgs_step_max_s: local::RK4_STEP_MAX_S,
        polish: false,
        local: LocalMethod::Lm,
    }
}
