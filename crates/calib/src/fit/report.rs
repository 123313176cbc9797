//! What a fit reports: per parameter, event, phase and stage, and the whole fit as text.

use serde::{Deserialize, Serialize};

use itaipu_dynamics::event::Channel;
use itaipu_dynamics::mode::PlaybackMode;

use crate::fit::{CORRELATION_LIMIT, CORRELATION_REPORT};
use crate::spec::{Objective, Weights};

/// Relative standard error up to which a parameter is **determined** by the data: 10 %, the
/// spread a datasheet value is typically trusted to (the models' typical ranges span about
/// ±10 % around a unit's value; a vendor's model is often off by 20-50 %). A fit that pins a
/// parameter tighter than the datasheet does has told the engineer something.
pub const DETERMINED_LIMIT: f64 = 0.10;
/// Relative standard error above which a parameter is **not determined**: a 1-σ interval that
/// holds zero (and any value of the same sign up to twice the estimate) says nothing of it.
pub const NOT_DETERMINED_LIMIT: f64 = 1.0;

/// How well the data determine a fitted parameter (see [`DETERMINED_LIMIT`],
/// [`NOT_DETERMINED_LIMIT`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Determination {
    /// Relative standard error at most [`DETERMINED_LIMIT`], not at a bound.
    Determined,
    /// Relative standard error between the two limits, not at a bound.
    Weak,
    /// Relative standard error above [`NOT_DETERMINED_LIMIT`], infinite or unknown (the data do
    /// not move the residuals along it), or the estimate at a bound (the standard error of a
    /// value held by its bound says nothing).
    NotDetermined,
}

impl Determination {
    /// The flag of a parameter with relative standard error `rel` (NaN: unknown).
    pub fn of(rel: f64, at_bound: bool) -> Self {
        if at_bound || !(rel <= NOT_DETERMINED_LIMIT) {
            Determination::NotDetermined
        } else if rel <= DETERMINED_LIMIT {
            Determination::Determined
        } else {
            Determination::Weak
        }
    }

    /// As the reports print it.
    pub fn label(self) -> &'static str {
        match self {
            Determination::Determined => "determined",
            Determination::Weak => "weak",
            Determination::NotDetermined => "not determined",
        }
    }
}

/// One parameter's line in a stage report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamReport {
    pub param: String,
    pub unit: String,
    pub start: f64,
    pub min: f64,
    pub max: f64,
    pub result: f64,
    /// Standard error from the Fisher approximation (∞ when not determined by the data).
    pub std_error: f64,
    /// `std_error / |result|` (∞ or NaN where the standard error is).
    pub relative_error: f64,
    pub determination: Determination,
    pub at_bound: bool,
    pub log_scaled: bool,
}

/// Goodness of fit of a stage at its optimum, as lmfit reports it: `n` data points (the P and Q
/// residuals over the fitted events' windows: the samples of RaPId's J), `k` free parameters,
/// `χ² = Σ (ΔP/σ_P)² + (ΔQ/σ_Q)²` with σ each event's noise floor ([`crate::noise`], the
/// calibrated unit's, as the report's noise table), the reduced `χ²/(n − k)`, and
/// `AIC = n ln(χ²/n) + 2k`, `BIC = n ln(χ²/n) + k ln n`. A reduced χ² near 1 is a fit at the
/// noise floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitStatistics {
    pub n_data: usize,
    pub n_free: usize,
    pub chi2: f64,
    pub reduced_chi2: f64,
    pub aic: f64,
    pub bic: f64,
}

impl FitStatistics {
    /// Not known yet (`k` free parameters): filled once the noise floors are.
    pub fn unknown(k: usize) -> Self {
        Self {
            n_data: 0,
            n_free: k,
            chi2: f64::NAN,
            reduced_chi2: f64::NAN,
            aic: f64::NAN,
            bic: f64::NAN,
        }
    }

    /// A stage's statistics from its P+Q fitness on the fitted events (`fitness`, held-out rows
    /// left out) and each event's noise floors `sigma(event) -> (σ_P, σ_Q)`.
    pub fn of_fitness(
        fitness: &[EventFitness],
        k: usize,
        sigma: impl Fn(&str) -> Option<(f64, f64)>,
    ) -> Self {
        let (mut chi2, mut n) = (0.0, 0usize);
        for f in fitness.iter().filter(|f| !f.held_out) {
            let Some((sp, sq)) = sigma(&f.event) else {
                return Self::unknown(k);
            };
            let m = f.samples as f64;
            chi2 += m * (f.rms_p / sp).powi(2) + m * (f.rms_q / sq).powi(2);
            n += 2 * f.samples;
        }
        if n == 0 {
            return Self::unknown(k);
        }
        Self::new(chi2, n, k)
    }

    /// From `chi2` over `n` terms with `k` free parameters.
    pub fn new(chi2: f64, n: usize, k: usize) -> Self {
        let nf = n as f64;
        let ll = nf * (chi2 / nf).ln();
        Self {
            n_data: n,
            n_free: k,
            chi2,
            reduced_chi2: if n > k {
                chi2 / (n - k) as f64
            } else {
                f64::NAN
            },
            aic: ll + 2.0 * k as f64,
            bic: ll + k as f64 * nf.ln(),
        }
    }
}

/// Objective values of the unit on one event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventFitness {
    pub event: String,
    /// Σ(ΔP² + ΔQ²) over the event's fit window (system base), RaPId's J. In a fit with
    /// playback modes, in the row's own mode (the stage's; the first stage's for the start row;
    /// in a P-held mode P is the measured one, so this is Σ ΔQ²).
    pub j_pq: f64,
    pub rms_p: f64,
    pub rms_q: f64,
    pub samples: usize,
    pub held_out: bool,
    /// In a fit with playback modes: the unit's fitness in every mode the fit uses (absent
    /// otherwise).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub modes: Vec<ModeFitness>,
}

/// The fitness of a unit on an event in one playback mode: per channel the mode simulates and
/// the record holds, the sum of squared differences over the fit window (pu: system base for P
/// and Q, machine base for |V|, E_fd, X_adI_fd), and `j`, the weighted sum over the channels the
/// fit compares in that mode (RaPId's fitness with its channels and equal weights).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModeFitness {
    pub mode: PlaybackMode,
    /// `Σ_c w_c Σ_k Δc²` over the compared channels; `None` when the mode's playback failed.
    pub j: Option<f64>,
    pub channels: Vec<ChannelFitness>,
    /// Why the playback failed (a unit without a grid equivalent in `closed_loop`, say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// One channel's misfit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelFitness {
    pub channel: Channel,
    /// Σ Δ² over the fit window.
    pub sse: f64,
    pub rms: f64,
    pub samples: usize,
    /// The weight the fit gives the channel in this mode (0: reported, not compared).
    pub weight: f64,
}

/// One phase's counters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseReport {
    pub phase: String,
    pub iterations: u64,
    pub best_objective: f64,
    pub stopped_by: String,
    /// A swarm's integration step attempts per sample its candidates played (its work; about 1
    /// for candidates followed at the record's resolution, `search::TOO_COSTLY_STEPS_PER_SAMPLE`
    /// gives up); 0 for a local phase and in reports written before it was kept.
    #[serde(default)]
    pub steps_per_sample: f64,
    /// Wall time of the phase [s] (0 in reports written before it was kept).
    #[serde(default)]
    pub wall_s: f64,
    /// Simulations the phase ran (its candidates' playbacks, the local method's Jacobians).
    #[serde(default)]
    pub simulations: usize,
}

/// The report of one stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageReport {
    pub stage: String,
    pub strategy: String,
    /// The stage's playback mode and compared channels (`"closed_loop: v 1, q 1, efd 1"`);
    /// absent for a phasor P+Q stage (then `objective` and `weights` say what it compares).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compare: Option<String>,
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
    /// Goodness of fit at the optimum (lmfit's statistics).
    pub statistics: FitStatistics,
    pub correlation: Vec<Vec<f64>>,
    /// Pairs with |ρ| above [`CORRELATION_REPORT`], strongest first: what moves together.
    pub correlations: Vec<(String, String, f64)>,
    /// Pairs with |ρ| above [`CORRELATION_LIMIT`]: not separately identifiable.
    pub correlated_pairs: Vec<(String, String, f64)>,
    /// Parameters in the numerical null space of the Jacobian: the residuals do not move
    /// along them (a subset of `not_determined`).
    pub unidentified: Vec<String>,
    /// [`Determination::Determined`] parameters, in the spec's order.
    pub determined: Vec<String>,
    /// [`Determination::Weak`] parameters.
    pub weak: Vec<String>,
    /// [`Determination::NotDetermined`] parameters.
    pub not_determined: Vec<String>,
    pub condition_number: f64,
    /// Channels an earlier pass compared that this pass made far worse
    /// ([`super::worsening`]); empty in reports written before it was measured.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub worsened: Vec<super::ChannelWorsening>,
}

/// The whole fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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

/// A number to 4 significant digits (scientific outside 1e-3..1e5).
fn sig(v: f64) -> String {
    if !v.is_finite() {
        return if v.is_nan() {
            "nan".into()
        } else {
            "inf".into()
        };
    }
    if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
        format!("{v:.3e}")
    } else {
        format!("{}", (v * 1e4).round() / 1e4)
    }
}

/// A relative error as a percentage.
fn rel_pct(r: f64) -> String {
    if r.is_finite() {
        format!("{:.1} %", 100.0 * r)
    } else {
        "-".into()
    }
}

/// Names joined with commas, or `none`.
fn list(v: &[String]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
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
            let objective = match &s.compare {
                Some(c) => format!("mode {c}"),
                None => format!("objective {:?}", s.objective),
            };
            let _ = writeln!(
                out,
                "stage {} ({}, {}): {:.5} -> {:.5}; {} simulations, \
                 {} failed candidates, {:.1} s",
                s.stage,
                s.strategy,
                objective,
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
            let st = &s.statistics;
            let _ = writeln!(
                out,
                "  fit statistics: {} data points, {} free parameters, chi-square {}, reduced \
                 chi-square {:.3}, AIC {:.1}, BIC {:.1}",
                st.n_data,
                st.n_free,
                sig(st.chi2),
                st.reduced_chi2,
                st.aic,
                st.bic
            );
            let _ = writeln!(
                out,
                "  {:<22} {:>11} {:>11} {:>9}  {:<22} {:>10} {:>21}",
                "parameter", "value", "std err", "rel err", "flag", "start", "bounds"
            );
            for p in &s.parameters {
                let _ = writeln!(
                    out,
                    "  {:<22} {:>11} {:>11} {:>9}  {:<22} {:>10} {:>10}-{:<10}",
                    p.param,
                    sig(p.result),
                    sig(p.std_error),
                    rel_pct(p.relative_error),
                    format!(
                        "{}{}",
                        p.determination.label(),
                        if p.at_bound { " (bound)" } else { "" }
                    ),
                    sig(p.start),
                    format!("{}", p.min),
                    format!("{}", p.max),
                );
            }
            if !s.correlations.is_empty() {
                let _ = writeln!(
                    out,
                    "  correlations above {CORRELATION_REPORT} ({} or more: not separately \
                     identifiable):",
                    CORRELATION_LIMIT
                );
                for (a, b, rho) in &s.correlations {
                    let _ = writeln!(out, "    C({a}, {b}) = {rho:+.3}");
                }
            }
            let _ = writeln!(
                out,
                "  determined (rel err <= {:.0} %): {}; weak: {}; not determined (rel err > \
                 {:.0} % or at a bound): {}",
                100.0 * DETERMINED_LIMIT,
                list(&s.determined),
                list(&s.weak),
                100.0 * NOT_DETERMINED_LIMIT,
                list(&s.not_determined)
            );
            for w in &s.worsened {
                let _ = writeln!(out, "  warning: {}", w.sentence());
            }
        }
        // With playback modes the P+Q J mixes what each stage compares: only the per-mode
        // table below, each mode's J in its own channels.
        let moded = r.start_fitness.iter().any(|f| !f.modes.is_empty());
        if !moded {
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
        }
        if moded {
            let _ = writeln!(out);
            let _ = writeln!(
                out,
                "fitness per playback mode: J = sum over the compared channels of sum(d^2) (pu), \
                 then each channel's sum(d^2) (* = compared; per event, * after the event = held out)"
            );
            let mode_rows = |out: &mut String, name: &str, f: &[EventFitness]| {
                for ev in f {
                    for m in &ev.modes {
                        let j = m.j.map_or("failed".to_string(), |j| format!("{j:.5}"));
                        let ch: Vec<String> = m
                            .channels
                            .iter()
                            .map(|c| {
                                format!(
                                    "{}{} {:.5}",
                                    c.channel,
                                    if c.weight > 0.0 { "*" } else { "" },
                                    c.sse
                                )
                            })
                            .collect();
                        let _ = writeln!(
                            out,
                            "  {:>10} {:<16} {:<17} J {:>12}   {}",
                            name,
                            format!("{}{}", ev.event, if ev.held_out { "*" } else { "" }),
                            m.mode,
                            j,
                            ch.join(", ")
                        );
                    }
                }
            };
            mode_rows(&mut out, "start", &r.start_fitness);
            for s in &r.stages {
                mode_rows(&mut out, &s.stage, &s.fitness);
            }
        }
        let _ = writeln!(out, "total {:.1} s on {} threads", r.wall_s, r.threads);
        out
    }
}
