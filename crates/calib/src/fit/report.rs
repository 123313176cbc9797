//! What a fit reports: per parameter, event, phase and stage, and the whole fit as text.

use serde::Serialize;

use crate::spec::{Objective, Weights};

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
