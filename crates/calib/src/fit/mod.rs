//! Staged calibration: generator, then AVR, PSS, governor, each by PSO then L-BFGS (paper 000
//! Algorithm 1), with the incremental and simultaneous-first strategies of paper 001.
//!
//! Per stage: the unit keeps or loses later stages' blocks ([`crate::spec::StageBlocks`]),
//! `set` values and `replace` blocks are applied, the swarm searches the stage's box from the
//! current values, L-BFGS refines the swarm's best, and the best of start / swarm / L-BFGS by
//! an accurate re-evaluation is kept. The Gauss-Newton (Fisher) approximation at that point
//! gives standard errors and correlations. Results carry over to the next stage.

mod passes;
mod report;
mod search;
mod stage;
pub mod worsening;

pub use passes::{fit, fit_with};
pub use report::{
    ChannelFitness, Determination, EventFitness, FitReport, FitStatistics, ModeFitness,
    ParamReport, PhaseReport, StageReport, DETERMINED_LIMIT, NOT_DETERMINED_LIMIT,
};
pub(crate) use search::{jacobian, search};
pub use stage::check_spec;
use stage::*;
pub use worsening::ChannelWorsening;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::mode::{simulate_mode, simulate_mode_traces, PlaybackMode};
use itaipu_dynamics::simulate::{simulate_prepared, Traces};
use itaipu_dynamics::unit::Unit;

use crate::local;
use crate::problem::{accurate_integrator, EventData, ProblemError};
use crate::spec::{CalibSpec, Compare, LocalMethod, Strategy};

/// Correlation above which two parameters are reported as not separately identifiable.
pub const CORRELATION_LIMIT: f64 = 0.95;
/// Correlation above which a pair is listed in a stage report (lmfit lists correlations above
/// a `min_correl` too): |ρ| = 0.8 means that 64 % of one estimate's variance moves with the
/// other's.
pub const CORRELATION_REPORT: f64 = 0.8;

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
    /// from the staged result, then the local method from the swarm's best and from the
    /// datasheet values; comparing what the stages compared unless `[calibration.joint]` says,
    /// [`CalibSpec::joint_compare_of`]), reported as the stage `joint`.
    pub polish: bool,
    /// The local method after each swarm.
    pub local: LocalMethod,
    /// When Levenberg-Marquardt counts as converged.
    pub lm_stop: local::LmStop,
    /// Starts of the local method after a stage's swarm: its best and up to `local_starts − 1`
    /// other particles' bests apart from it ([`search::distinct_bests`]; `[calibration.pso]
    /// local_starts`). 1: the swarm's best alone.
    pub local_starts: usize,
    /// Swarm iterations of the joint pass (`[calibration.pso] joint_iterations`); `None`: the
    /// stages' [`FitOptions::pso_iterations`] ([`FitOptions::joint_pass`]).
    pub joint_pso_iterations: Option<usize>,
    /// The swarm's playbacks: [`crate::problem::search_integrator`] in a calibration,
    /// [`crate::problem::refit_search_integrator`] in a diagnosis re-fit.
    pub swarm_integrator: itaipu_dynamics::simulate::SimOptions,
}

impl FitOptions {
    /// Checks what the swarm cannot run with: a swarm of no particle (the spec parser and the
    /// front ends refuse fewer than 2; a program may set anything).
    pub fn check(&self) -> Result<(), FitError> {
        if self.particles == 0 && self.pso_iterations > 0 {
            return Err(FitError::Setup(
                "particles must be at least 1 (or pso_iterations 0)".into(),
            ));
        }
        Ok(())
    }

    /// The joint pass's swarm iterations: its own where set, else the stages'.
    pub fn joint_iterations(&self) -> usize {
        self.joint_pso_iterations.unwrap_or(self.pso_iterations)
    }

    /// The options of the joint pass: its own swarm budget ([`FitOptions::joint_iterations`]),
    /// whose swarm starts from the staged result, and the swarm's best alone handed to the
    /// local method (`local_starts` is the stages'), which the caller also starts from the
    /// datasheet values.
    pub fn joint_pass(&self) -> FitOptions {
        FitOptions {
            pso_iterations: self.joint_iterations(),
            joint_pso_iterations: None,
            local_starts: 1,
            ..self.clone()
        }
    }

    /// Options from a spec, running every stage it lists.
    pub fn from_spec(spec: &CalibSpec) -> Self {
        Self {
            stages: spec.stages.iter().map(|s| s.name.clone()).collect(),
            strategy: spec.strategy,
            seed: spec.seed,
            particles: spec.pso.particles,
            pso_iterations: spec.pso.iterations,
            local_starts: spec.pso.local_starts,
            joint_pso_iterations: spec.pso.joint_iterations,
            lbfgs_iterations: spec.lbfgs.iterations,
            lbfgs_memory: spec.lbfgs.memory,
            lbfgs_step_max_s: local::RK4_STEP_MAX_S,
            polish: spec.polish,
            local: spec.local,
            lm_stop: local::LmStop::CALIBRATION,
            swarm_integrator: crate::problem::search_integrator(),
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
    /// An event does not hold what a stage plays back or compares (no angle for a phasor
    /// stage, no E_fd for the exciter alone, a compared channel it did not record).
    #[error("{0}")]
    Event(String),
    /// The starting unit does not simulate on a fitted event (it cannot initialise at the
    /// measured operating point, or the integration fails); the engine's error is kept.
    #[error("the starting unit: {0}")]
    Start(ProblemError),
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
            FitError::Event(_) => "event",
            FitError::Start(_) => "start",
            FitError::Interrupted { .. } => "interrupted",
            FitError::Output(_) => "output",
        }
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
/// (every stage's results so far) that the next pass starts from. A hook that fails (an output
/// it could not write, say) returns [`FitError::Output`], which stops the fit.
pub type OnStage<'a> =
    dyn Fn(&StageReport, &StageOutput, &Unit) -> Result<(), FitError> + Sync + 'a;

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
    pub(super) fn cancelled(&self) -> bool {
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
) -> Result<(EventFitness, Traces), ProblemError> {
    let data = EventData::new(event, None, None)?;
    let mut u = unit.clone();
    let tr = simulate_prepared(&mut u, &data.prepared, event, &accurate_integrator()).map_err(
        |error| ProblemError::Simulation {
            event: event.name.clone(),
            error,
        },
    )?;
    // Every simulation records p_pu and q_pu (`simulate_prepared`'s fixed columns).
    let (Some(p), Some(q)) = (tr.get("p_pu"), tr.get("q_pu")) else {
        return Err(ProblemError::Diverged {
            event: event.name.clone(),
            t: f64::NAN,
        });
    };
    let f = pq_fitness(event, data.window_sums(p, q), held_out, vec![]);
    Ok((f, tr))
}

/// An event's P+Q fitness from its window sums (J with unit weights, RMS per channel), with
/// the per-mode rows `modes`.
fn pq_fitness(
    event: &Event,
    s: crate::problem::WindowSums,
    held_out: bool,
    modes: Vec<ModeFitness>,
) -> EventFitness {
    let nn = s.n.max(1) as f64;
    EventFitness {
        event: event.name.clone(),
        j_pq: s.j((1.0, 1.0)),
        rms_p: (s.p / nn).sqrt(),
        rms_q: (s.q / nn).sqrt(),
        samples: s.n,
        held_out,
        modes,
    }
}

/// The fitness row of `unit` on `event` in a fit with playback modes: `rows` the fit's
/// comparisons ([`CalibSpec::compares`]; empty: the historical P+Q row of [`fitness`]),
/// `primary` the row's own comparison (the stage's; `None`: the phasor P+Q). `j_pq`, the RMS
/// values and the traces come from the primary mode; [`EventFitness::modes`] holds every mode of
/// `rows` (a mode that cannot play the unit back is reported with its error, unless it is the
/// primary one).
pub fn row_fitness(
    unit: &Unit,
    event: &Event,
    held_out: bool,
    rows: &[Compare],
    primary: Option<&Compare>,
) -> Result<(EventFitness, Traces), ProblemError> {
    if rows.is_empty() && primary.is_none() {
        return fitness(unit, event, held_out);
    }
    let data = EventData::new(event, None, None)?;
    let acc = accurate_integrator();
    let sim_err = |error| ProblemError::Simulation {
        event: event.name.clone(),
        error,
    };
    let pmode = primary.map_or(PlaybackMode::Phasor, |c| c.mode);
    let mut modes = vec![];
    let mut primary_pq = None;
    for cmp in rows {
        let out = simulate_mode(unit, &data.prepared, cmp.mode, &acc);
        let out = match out {
            Ok(o) => o,
            Err(e) if cmp.mode != pmode => {
                modes.push(ModeFitness {
                    mode: cmp.mode,
                    j: None,
                    channels: vec![],
                    error: Some(e.to_string()),
                });
                continue;
            }
            Err(e) => return Err(sim_err(e)),
        };
        let reported: Vec<Channel> = cmp
            .mode
            .outputs()
            .iter()
            .copied()
            .filter(|c| event.has(*c))
            .collect();
        let sums = data.channel_sums(&out, &reported);
        let weight = |c: Channel| {
            cmp.weights
                .iter()
                .find(|(x, _)| *x == c)
                .map_or(0.0, |(_, w)| *w)
        };
        let j: f64 = sums.iter().map(|(c, s, _)| weight(*c) * s).sum();
        modes.push(ModeFitness {
            mode: cmp.mode,
            j: j.is_finite().then_some(j),
            channels: sums
                .iter()
                .map(|&(c, sse, n)| ChannelFitness {
                    channel: c,
                    sse,
                    rms: (sse / n.max(1) as f64).sqrt(),
                    samples: n,
                    weight: weight(c),
                })
                .collect(),
            error: None,
        });
        if cmp.mode == pmode {
            primary_pq = Some((out.p, out.q));
        }
    }
    let (p, q) = match primary_pq {
        Some(pq) => pq,
        None => {
            let o = simulate_mode(unit, &data.prepared, pmode, &acc).map_err(sim_err)?;
            (o.p, o.q)
        }
    };
    let f = pq_fitness(event, data.window_sums(&p, &q), held_out, modes);
    let tr = simulate_mode_traces(unit, event, pmode, &acc).map_err(sim_err)?;
    Ok((f, tr))
}

/// Checks, before anything runs, that every event holds what the stages to run play back and
/// compare (and the joint pass when `joint`): an event without an angle in a phasor stage, or
/// without a channel a stage compares, is a setup error naming the event's file, the channel
/// and the stage's field in the spec.
pub fn check_events(
    spec: &CalibSpec,
    spec_file: Option<&std::path::Path>,
    stages: &[String],
    joint: bool,
    events: &[Event],
    held_out: &[Event],
) -> Result<(), FitError> {
    let of = spec_file.map_or(String::new(), |p| format!(" of {}", p.display()));
    let legacy = |st: &crate::spec::StageSpec| {
        let (wp, wq) = crate::problem::objective_weights(st.objective, st.weights);
        Compare {
            mode: PlaybackMode::Phasor,
            weights: [(Channel::P, wp), (Channel::Q, wq)]
                .into_iter()
                .filter(|(_, w)| *w > 0.0)
                .collect(),
        }
    };
    let mut checks: Vec<(String, Compare)> = vec![];
    for s in stages {
        let Some(k) = spec.stages.iter().position(|st| &st.name == s) else {
            continue;
        };
        let st = &spec.stages[k];
        let cmp = st.compare().unwrap_or_else(|| legacy(st));
        let field = if st.compare().is_some() {
            format!(
                "calibration.stage[{k}] (stage {s}, mode {}, channels)",
                cmp.mode
            )
        } else {
            format!("calibration.stage[{k}] (stage {s}, phasor playback)")
        };
        checks.push((field, cmp));
    }
    if joint {
        if let Some(c) = spec.joint_compare_of(stages) {
            checks.push((format!("calibration.joint (mode {}, channels)", c.mode), c));
        }
    }
    for e in events.iter().chain(held_out) {
        for (field, cmp) in &checks {
            if let Some(why) = cmp.mode.missing(e, &cmp.channels()) {
                let file = e.toml_path.as_ref().map_or_else(
                    || format!("<in-memory event '{}'>", e.name),
                    |p| p.display().to_string(),
                );
                return Err(FitError::Event(format!(
                    "{file}: event '{}' {why}; {field}{of} needs it",
                    e.name
                )));
            }
        }
    }
    Ok(())
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
        lm_stop: local::LmStop::CALIBRATION,
        local_starts: 1,
        joint_pso_iterations: None,
        swarm_integrator: crate::problem::search_integrator(),
    }
}
