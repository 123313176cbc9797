//! One stage (or the simultaneous or joint pass): the stage spec applied to the unit (`set`,
//! `replace`, ties), its free parameters resolved, the spec checked before any simulation, and
//! the stage run (search, accurate re-evaluation, identifiability, traces).

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit::{ParamRef, Unit};
use itaipu_dynamics::unit_file;

use crate::bounds::{BoundProblem, PriorSource};
use crate::identify;
use crate::problem::{
    accurate_integrator, objective_weights, sum_of_squares, EventData, FreeParam, Problem,
};
use crate::spec::{CalibSpec, Channels, Compare, Objective, StageSpec, Strategy, Weights};

use super::*;

pub(super) fn stage_err(stage: &str, msg: impl Into<String>) -> FitError {
    FitError::Stage {
        stage: stage.to_string(),
        msg: msg.into(),
    }
}

/// Applies a stage's `set` and `replace` entries to the master unit.
pub(super) fn apply_stage_edits(master: &mut Unit, spec: &StageSpec) -> Result<(), FitError> {
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
pub(super) fn build_block(
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
/// passes), comparing what [`CalibSpec::joint_compare_of`] says (`[calibration.joint]`'s
/// channels, else what the stages compared; P+Q when that is P and Q), with the joint table's
/// window and extra free parameters.
pub(super) fn combined_stage(name: &str, spec: &CalibSpec, stages: &[String]) -> StageSpec {
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
        mode: Default::default(),
        channels: None,
    };
    if let Some(c) = spec.joint_compare_of(stages) {
        all.mode = c.mode;
        all.channels = Some(Channels::Weights(
            c.weights
                .iter()
                .map(|(ch, w)| (ch.name().to_string(), *w))
                .collect(),
        ));
    }
    if let Some(j) = &spec.joint {
        all.window = j.window;
    }
    for s in stages {
        let st = spec.stage(s).expect("stages are checked against the spec");
        all.free.extend(st.free.iter().cloned());
        all.tie
            .extend(st.tie.iter().map(|(a, b)| (a.clone(), b.clone())));
        all.window = all.window.or(st.window);
        all.lowpass_hz = all.lowpass_hz.or(st.lowpass_hz);
    }
    if let Some(j) = &spec.joint {
        for f in &j.free {
            if !all.free.iter().any(|g| g.param == f.param) {
                all.free.push(f.clone());
            }
        }
    }
    all
}

/// Resolves a stage's free parameters in `unit`, each with its prior around its value in
/// `datasheet` (the unit before the fit) with the parameter's spread or `default_spread`.
pub(super) fn free_params(
    unit: &Unit,
    spec: &StageSpec,
    datasheet: &Unit,
    default_spread: f64,
) -> Result<Vec<FreeParam>, FitError> {
    crate::bounds::resolve(
        unit,
        &spec.free,
        PriorSource::Datasheet {
            datasheet,
            default_spread,
        },
    )
    .map_err(|e| match e.problem {
        BoundProblem::Unknown(_) => stage_err(
            &spec.name,
            format!("{e} (is its block part of this stage?)"),
        ),
        _ => stage_err(&spec.name, e.to_string()),
    })
}

/// Resolves a stage's ties `to = from` in `unit` as `(from, to)` references.
pub(super) fn resolve_ties(
    unit: &Unit,
    spec: &StageSpec,
) -> Result<Vec<(ParamRef, ParamRef)>, FitError> {
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
pub(super) fn apply_ties(unit: &mut Unit, spec: &StageSpec) -> Result<(), FitError> {
    for (from, to) in resolve_ties(unit, spec)? {
        let v = unit.get(from);
        unit.set(to, v);
    }
    Ok(())
}

/// Identifiability results in parameter names.
pub(super) struct Ident {
    std_errors: Vec<f64>,
    correlation: Vec<Vec<f64>>,
    pairs: Vec<(String, String, f64)>,
    unidentified: Vec<String>,
    sigma2: f64,
    condition: f64,
}

/// Runs a stage (or the simultaneous pass) on `unit` with `free` parameters.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_stage(
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
    rows: &[Compare],
) -> Result<(StageReport, StageOutput, Vec<f64>), FitError> {
    let t0 = Instant::now();
    let data: Vec<EventData> = events
        .iter()
        .map(|e| EventData::new(e, spec.window, spec.lowpass_hz))
        .collect::<Result<_, _>>()
        .map_err(|m| stage_err(name, m.to_string()))?;
    let weights = objective_weights(spec.objective, spec.weights);
    let ties = resolve_ties(&unit, spec)?;
    let mut problem = Problem::new(unit, free, data, weights);
    problem.ties = ties;
    problem.cancel = cancel;
    problem.compare = spec.compare();
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
            sub.compare = problem.compare.clone();
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
    let parameters: Vec<ParamReport> = problem
        .free
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let at_bound = f.at_bound(best[i]);
            let relative_error = std_errors[i] / best[i].abs();
            ParamReport {
                param: f.path.clone(),
                unit: f.unit.to_string(),
                start: f.start,
                min: f.lo,
                max: f.hi,
                result: best[i],
                std_error: std_errors[i],
                relative_error,
                determination: Determination::of(relative_error, at_bound),
                at_bound,
                log_scaled: f.log,
            }
        })
        .collect();
    // A phasor stage's: filled by the job once the noise floors are known
    // ([`crate::job::run_fit`]).
    let statistics = mode_statistics(&problem, &best, &acc)
        .map_err(|m| stage_err(name, format!("the calibrated unit does not simulate: {m}")))?
        .unwrap_or_else(|| FitStatistics::unknown(problem.dim()));
    let with = |d: Determination| -> Vec<String> {
        parameters
            .iter()
            .filter(|p| p.determination == d)
            .map(|p| p.param.clone())
            .collect()
    };
    let (determined, weak, not_determined) = (
        with(Determination::Determined),
        with(Determination::Weak),
        with(Determination::NotDetermined),
    );
    let correlations = strong_correlations(&problem, &correlation);

    let start_unit = problem.unit_at(&start);
    let calibrated_unit = problem.unit_at(&best);
    let mut fitness_rows = vec![];
    let mut traces = vec![];
    let own = problem.compare.clone();
    for e in events {
        let (fs, tr_end) = row_fitness(&calibrated_unit, e, false, rows, own.as_ref())
            .map_err(|m| stage_err(name, m.to_string()))?;
        let (_, tr_start) = row_fitness(&start_unit, e, false, rows, own.as_ref())
            .map_err(|m| stage_err(name, m.to_string()))?;
        fitness_rows.push(fs);
        traces.push((e.name.clone(), tr_start, tr_end));
    }
    for e in held_out {
        // A held-out event that the calibrated unit cannot simulate is reported, not fatal.
        match row_fitness(&calibrated_unit, e, true, rows, own.as_ref()) {
            Ok((fs, _)) => fitness_rows.push(fs),
            Err(m) => progress.message(&format!("{label}: held-out event {}: {m}", e.name)),
        }
    }
    let report = StageReport {
        stage: label.to_string(),
        strategy: opts.strategy.to_string(),
        compare: problem.compare.as_ref().map(|c| c.describe()),
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
        statistics,
        correlation,
        correlations,
        correlated_pairs: pairs,
        unidentified,
        determined,
        weak,
        not_determined,
        condition_number: cond,
        worsened: vec![],
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

/// lmfit's goodness-of-fit statistics of a stage that compares channels of a playback mode
/// (`problem.compare`: E_fd, Q, |V|, …) at `x` ([`FitStatistics`]): each compared channel in
/// units of its measured noise. A phasor stage's statistics are filled by the job from its P+Q
/// fitness and the noise floors ([`crate::job::run_fit`]).
fn mode_statistics(
    problem: &Problem,
    x: &[f64],
    sim: &itaipu_dynamics::simulate::SimOptions,
) -> Result<Option<FitStatistics>, crate::problem::ProblemError> {
    let Some(cmp) = &problem.compare else {
        return Ok(None);
    };
    let outs = problem.simulate_outputs(x, sim)?;
    let (mut chi2, mut n) = (0.0, 0usize);
    for (ev, out) in problem.events.iter().zip(&outs) {
        for &(c, _) in &cmp.weights {
            let var = ev.channel_noise_variance(c).max(f64::MIN_POSITIVE);
            let (Some(s), Some(m)) = (out.channel(c), ev.measured(c)) else {
                continue;
            };
            for k in (0..s.len()).filter(|&k| ev.in_window[k]) {
                chi2 += (s[k] - m[k]).powi(2) / var;
                n += 1;
            }
        }
    }
    Ok(Some(FitStatistics::new(chi2, n, problem.dim())))
}

/// The pairs of `problem`'s parameters whose estimates correlate above [`CORRELATION_REPORT`]
/// (`correlation` from the identifiability analysis; NaN entries left out), strongest first.
fn strong_correlations(problem: &Problem, correlation: &[Vec<f64>]) -> Vec<(String, String, f64)> {
    let mut out = vec![];
    for (i, row) in correlation.iter().enumerate() {
        for (j, rho) in row.iter().enumerate().skip(i + 1) {
            if rho.abs() > CORRELATION_REPORT {
                out.push((
                    problem.free[i].path.clone(),
                    problem.free[j].path.clone(),
                    *rho,
                ));
            }
        }
    }
    out.sort_by(|a, b| b.2.abs().total_cmp(&a.2.abs()));
    out
}
