//! Diagnosis: what a calibrated unit still gets wrong on measured events, which cause in the
//! [`catalog`] explains it, the extended and re-fitted model, and the gain.
//!
//! # Procedure
//!
//! 1. **Evidence.** Each event is played back through the unit as given; the residuals
//!    `r = simulated − measured` of P and Q (and E_fd, I_fd where measured) are analysed by
//!    [`crate::evidence::analyse`] in four windows (pre-event, dip = the first second after the
//!    event, recovery = the next 4 s, tail), against the inputs |V| and frequency.
//! 2. **Noise.** σ_P, σ_Q are the standard deviations of the pre-event residual of the unit as
//!    given (where a right model is in steady state), so that
//!    `χ² = Σ (ΔP/σ_P)² + Σ (ΔQ/σ_Q)²` is in units of the noise variance, the playback's input
//!    noise propagated through the model included. The set-point offsets are then re-fitted
//!    (nuisance parameters): the evidence and the verdict are about that reference.
//! 3. **Split.** With held-out events, the candidates are fitted on the events and judged on the
//!    held-out ones. Without, each event is cut into alternating blocks of
//!    [`DiagnoseOptions::block_s`] seconds: even blocks are fitted, odd blocks held out.
//! 4. **Candidates.** For each applicable cause, the unit is extended ([`catalog::extend`]) and
//!    re-fitted over the extension's parameters and the unit parameters it interacts with: a grid
//!    scan of the narrow-valleyed ones, the swarm, the scan again, L-BFGS. The
//!    **baseline** is the unit re-fitted over the same interacting parameters without the
//!    extension, so a gain is the extension's alone.
//! 5. **Gain.** `Δχ²` on the fitted samples, the relative drop of the fitted and of the held-out
//!    χ², each net of the gain the same re-fits achieve on a surrogate of the events (the
//!    reference's own simulation with the noise drawn again: pure noise fitting), and the
//!    Bayesian information criterion difference `ΔBIC = Δχ²/VIF − k ln(N/VIF)` (k = the
//!    extension's parameters, N = fitted residuals, VIF = `(1 + ρ₁)/(1 − ρ₁)` from the baseline
//!    residual's lag-1 autocorrelation, so that a coloured residual counts as fewer independent
//!    samples): an extension that only buys flexibility gains about `k` in χ² and loses.
//! 6. **Verdict.** A candidate is significant when `ΔBIC > bic_threshold`, its fitted χ² is down
//!    by at least `min_fit_drop` and its held-out χ² by at least `min_held_drop`. Among the
//!    significant ones, the extended model with the lowest `χ²_ext + k ln N` (k = every
//!    parameter it re-fitted) is named. Otherwise the verdict is `none` (residual RMS within
//!    `noise_factor` of the noise floor) or `unexplained` (with the window and signal where the
//!    residual lives).
//!
//! The residuals of a calibrated model are rarely white, so χ² overstates the evidence when the
//! model error dominates the noise; the held-out check and the relative-drop threshold guard
//! against naming a cause that only absorbs some structured misfit.

pub mod catalog;
pub mod causes;
pub mod trial;
pub mod user_cause;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::{ParamRef, Unit};
use serde::Serialize;

use crate::evidence::{self, EvidenceOptions, SignalEvidence};
use crate::fit::{fitness, search, FitOptions, Progress};
use crate::problem::{
    accurate_integrator, search_integrator, sum_of_squares, EventData, FreeParam, Problem,
};
use crate::spec::Strategy;
use catalog::{Context, Extension, FreeBound, CAUSES};

/// Options of a diagnosis.
#[derive(Debug, Clone)]
pub struct DiagnoseOptions {
    /// Causes to try (ids from [`catalog::CAUSES`]); empty = the whole catalog.
    pub causes: Vec<String>,
    /// Causes written by the user ([`user_cause`]), tried after the catalog's (or named in
    /// `causes`).
    pub user_causes: Vec<user_cause::UserCause>,
    /// Calibrated parameters to free again in every re-fit (baselines and extensions alike),
    /// with their bounds: the parameters a calibration without the cause may have bent to make
    /// up for it (typically the stage parameters of the preceding fit). Empty = only each
    /// cause's own interacting parameters.
    pub refit: Vec<FreeBound>,
    pub seed: u64,
    pub particles: usize,
    pub pso_iterations: usize,
    pub lbfgs_iterations: u64,
    pub lbfgs_memory: usize,
    /// Block length of the fit/held-out split of an event [s].
    pub block_s: f64,
    /// ΔBIC above which a gain counts (10 = "very strong" on the Kass-Raftery scale).
    pub bic_threshold: f64,
    /// Smallest relative drop of the fitted χ² for a cause to be named.
    pub min_fit_drop: f64,
    /// Smallest relative drop of the held-out χ².
    pub min_held_drop: f64,
    /// Residual RMS up to this multiple of the noise floor counts as "at the noise floor".
    pub noise_factor: f64,
    /// When set (by a signal handler, say), every later candidate evaluation of the re-fits
    /// fails at once and the diagnosis returns [`DiagnoseError::Interrupted`] with the causes
    /// it finished.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl DiagnoseOptions {
    fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            causes: vec![],
            user_causes: vec![],
            refit: vec![],
            seed: 1,
            particles: 16,
            pso_iterations: 20,
            lbfgs_iterations: 15,
            lbfgs_memory: 7,
            block_s: 0.5,
            bic_threshold: 10.0,
            min_fit_drop: 0.02,
            min_held_drop: 0.01,
            noise_factor: 1.5,
            cancel: None,
        }
    }
}

/// Why a diagnosis could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DiagnoseError {
    /// Bad request (unknown cause, no event).
    #[error("{0}")]
    Setup(String),
    /// The unit does not simulate on an event as given.
    #[error("the unit does not simulate on event '{event}': {msg}")]
    Simulation { event: String, msg: String },
    /// Stopped by [`DiagnoseOptions::cancel`]; `tried` lists the causes tried up to then (the
    /// last one possibly cut short). Nothing of the run is kept.
    #[error("interrupted (causes tried: {})", if tried.is_empty() { "none".to_string() } else { tried.join(", ") })]
    Interrupted { tried: Vec<String> },
}

impl DiagnoseError {
    pub fn kind(&self) -> &'static str {
        match self {
            DiagnoseError::Setup(_) => "setup",
            DiagnoseError::Simulation { .. } => "simulation",
            DiagnoseError::Interrupted { .. } => "interrupted",
        }
    }
}

/// Evidence for one event.
#[derive(Debug, Clone, Serialize)]
pub struct EventEvidence {
    pub event: String,
    /// Event onset used for the windows [s].
    pub onset_s: f64,
    pub signals: Vec<SignalEvidence>,
    /// The strongest resonance of the P residual in the shaft band (see [`SHAFT_BAND_HZ`]).
    pub p_peak: Option<evidence::SpectralPeak>,
}

/// Band searched for a torsional line in the P residual [Hz]: above the electromechanical and
/// control modes (below 3 Hz), up to 25 Hz (the first torsional modes of hydro and thermal
/// shafts lie between about 5 and 25 Hz), and below 0.95 × Nyquist.
pub const SHAFT_BAND_HZ: (f64, f64) = (4.0, 25.0);

/// A re-fitted parameter of a candidate.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateParam {
    pub param: String,
    pub unit: String,
    pub start: f64,
    pub min: f64,
    pub max: f64,
    pub result: f64,
    /// `true` for the extension's own parameters, `false` for interacting unit parameters.
    pub extension: bool,
    pub at_bound: bool,
    /// Standard error at the re-fit's optimum, from the Jacobian of the residuals with the
    /// priors' rows (a posterior standard error, every re-fitted parameter free): computed for
    /// the named cause only (`null` otherwise, ∞ when the data and prior do not determine it).
    pub std_error: Option<f64>,
}

/// The gain of an extension.
#[derive(Debug, Clone, Serialize)]
pub struct Gains {
    /// χ² of the baseline re-fit on the fitted samples.
    pub chi2_fit_base: f64,
    pub chi2_fit_ext: f64,
    pub chi2_held_base: f64,
    pub chi2_held_ext: f64,
    /// χ² drop the same re-fit achieves on the surrogate events, where the reference model is
    /// exact and only noise can be fitted (fitted and held-out samples).
    pub null_gain_fit: f64,
    pub null_gain_held: f64,
    /// Net relative drop on the fitted samples:
    /// `(chi2_fit_base − chi2_fit_ext − null_gain_fit)/chi2_fit_base`.
    pub fit_drop: f64,
    /// Net relative drop on the held-out samples, likewise.
    pub held_drop: f64,
    /// `Δχ²/VIF − k ln(N/VIF)` with the net `Δχ²`: the BIC difference with the χ² difference
    /// and the sample size deflated by the baseline residual's variance inflation (positive
    /// favours the extension).
    pub delta_bic: f64,
    /// Variance inflation factor of the baseline residual (1 for white noise).
    pub vif: f64,
    /// Parameters counted (the extension's, plus discrete switches).
    pub k: usize,
    pub n_fit: usize,
    pub n_held: usize,
    /// RMS of P and Q over all samples, before (baseline) and after [pu system base].
    pub rms_p_base: f64,
    pub rms_q_base: f64,
    pub rms_p_ext: f64,
    pub rms_q_ext: f64,
}

/// One cause tried.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateReport {
    pub cause: String,
    pub title: String,
    /// `false` when the cause does not apply to this unit (see `note`).
    pub applicable: bool,
    pub note: String,
    pub extension: String,
    pub parameters: Vec<CandidateParam>,
    /// Structural results (e.g. `pss.in_service`).
    pub fixed: Vec<(String, f64)>,
    pub gains: Option<Gains>,
    pub significant: bool,
    /// What in the evidence points to (or away from) this cause.
    pub signature: Vec<String>,
    pub simulations: usize,
    pub failed_candidates: usize,
    pub wall_s: f64,
    /// The calibrated parameters (with a datasheet prior) that the baseline holds more than one
    /// prior spread from their datasheet value, or that the extension does: what the base model
    /// bends to mimic the cause, and where they go with the extension.
    pub distortion: Vec<Distortion>,
}

/// A calibrated parameter's value in the datasheet, the re-fitted baseline and the extension.
#[derive(Debug, Clone, Serialize)]
pub struct Distortion {
    pub param: String,
    pub datasheet: f64,
    pub base: f64,
    pub extended: f64,
    /// `ln(value/datasheet)/spread` of the baseline and of the extension (prior standard scores).
    pub z_base: f64,
    pub z_extended: f64,
}

/// The distortion a cause removes: for every re-freed parameter with a prior, its baseline and
/// extension values, kept where either lies more than one prior spread from the datasheet.
fn distortion(refit: &[FreeBound], base: &Unit, ext: &Unit) -> Vec<Distortion> {
    refit
        .iter()
        .filter_map(|b| {
            let p = b.prior?;
            let get = |u: &Unit| u.param(&b.param).ok().map(|r| u.get(r));
            let (vb, ve) = (get(base)?, get(ext)?);
            let (zb, ze) = (p.z(vb)?, p.z(ve)?);
            (zb.abs() > 1.0 || ze.abs() > 1.0).then(|| Distortion {
                param: b.param.clone(),
                datasheet: p.center,
                base: vb,
                extended: ve,
                z_base: zb,
                z_extended: ze,
            })
        })
        .collect()
}

/// The verdict.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    /// A cause id, `none`, or `unexplained`.
    pub cause: String,
    pub title: String,
    /// One paragraph for a person.
    pub statement: String,
    /// The named cause's key parameters `(path, value, unit)`.
    pub key_parameters: Vec<(String, f64, String)>,
    pub gains: Option<Gains>,
    /// Where the residual lives: `(signal, window, start_s, end_s)`.
    #[serde(rename = "where")]
    pub where_: Option<(String, String, f64, f64)>,
}

/// Noise and split.
#[derive(Debug, Clone, Serialize)]
pub struct NoiseModel {
    pub sigma_p: f64,
    pub sigma_q: f64,
    pub split: String,
    pub n_fit: usize,
    pub n_held: usize,
}

/// Everything `diagnose` reports (written as JSON by the CLI).
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub unit: String,
    pub events: Vec<String>,
    pub held_out: Vec<String>,
    pub verdict: Verdict,
    /// Candidates: the significant ones first, by the BIC of their extended model
    /// (χ²_ext + k ln N, lowest first), then the others by decreasing ΔBIC (not applicable
    /// ones last).
    pub candidates: Vec<CandidateReport>,
    pub evidence: Vec<EventEvidence>,
    /// Evidence with the named extension (empty when none is named).
    pub evidence_after: Vec<EventEvidence>,
    pub noise: NoiseModel,
    /// Calibrated parameters freed again in every re-fit ([`DiagnoseOptions::refit`]).
    pub refit: Vec<FreeBound>,
    pub seed: u64,
    pub threads: usize,
    pub wall_s: f64,
}

/// Result of [`diagnose`].
pub struct DiagnoseResult {
    pub report: Diagnosis,
    /// The extended, re-fitted unit of the named cause.
    pub extended_unit: Option<Unit>,
    /// Per event: traces of the unit as given.
    pub before: Vec<(String, Traces)>,
    /// Per event: traces of the extended unit (empty when none is named).
    pub after: Vec<(String, Traces)>,
}

/// Width of the "dip" window after the onset [s].
const DIP_S: f64 = 1.0;
/// Width of the "recovery" window after the dip [s].
const RECOVERY_S: f64 = 4.0;

/// The evidence windows of an event: pre-event up to the onset (the end of the event's init
/// window), dip, recovery, tail.
pub fn windows(event: &Event) -> (f64, Vec<(String, f64, f64)>) {
    let t = &event.record.time_s;
    let (t0, t1) = (t[0], *t.last().expect("events have samples"));
    let onset = event.init.end_s.clamp(t0, t1);
    let w = vec![
        ("pre-event".to_string(), t0, onset),
        ("dip".to_string(), onset, (onset + DIP_S).min(t1)),
        (
            "recovery".to_string(),
            (onset + DIP_S).min(t1),
            (onset + DIP_S + RECOVERY_S).min(t1),
        ),
        (
            "tail".to_string(),
            (onset + DIP_S + RECOVERY_S).min(t1),
            t1 + 1e-9,
        ),
    ];
    (onset, w.into_iter().filter(|(_, a, b)| b > a).collect())
}

/// How hard the events drive the unit, for [`Context`]: the deepest voltage dip after the
/// onset as a fraction of the pre-event |V|, and the largest sustained frequency change (mean
/// of the last quarter of the record against the pre-event mean) [Hz], over all events.
fn regime(events: &[Event]) -> (f64, f64) {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let (mut dip, mut df) = (0.0_f64, 0.0_f64);
    for e in events {
        let (pre, v0) = pre_event_v(e);
        let v = &e.record.v_mag_pu;
        let v_min = v[pre..].iter().copied().fold(v0, f64::min);
        dip = dip.max(1.0 - v_min / v0);
        let f = frequency_deviation(e);
        let tail = f.len() - f.len() / 4;
        df = df.max((mean(&f[tail..]) - mean(&f[..pre.min(f.len())])).abs());
    }
    (dip, df)
}

/// The samples of the event's init window (at least one) and their mean |V|: the pre-event
/// voltage against which dips and disturbances are measured.
fn pre_event_v(event: &Event) -> (usize, f64) {
    let r = &event.record;
    let pre = r
        .time_s
        .iter()
        .take_while(|&&t| t <= event.init.end_s)
        .count()
        .clamp(1, r.v_mag_pu.len());
    let v = &r.v_mag_pu[..pre];
    (pre, v.iter().sum::<f64>() / pre as f64)
}

/// Grid frequency deviation [Hz] from the record (`freq_hz` if present, else the derivative of
/// the unwrapped angle).
fn frequency_deviation(event: &Event) -> Vec<f64> {
    let r = &event.record;
    if let Some(f) = &r.freq_hz {
        return f.iter().map(|v| v - event.nominal_hz).collect();
    }
    let (t, a) = (&r.time_s, &r.v_ang_rad);
    let n = t.len();
    (0..n)
        .map(|k| {
            let (i, j) = (k.saturating_sub(1), (k + 1).min(n - 1));
            if j > i {
                (a[j] - a[i]) / (t[j] - t[i]) / (2.0 * std::f64::consts::PI)
            } else {
                0.0
            }
        })
        .collect()
}

/// Residual evidence of `traces` (simulated with the unit) against `event`.
pub fn event_evidence(event: &Event, traces: &Traces) -> EventEvidence {
    let (onset, win) = windows(event);
    let r = &event.record;
    let opts = EvidenceOptions {
        windows: win,
        noise_window: (r.time_s[0], onset),
        ..Default::default()
    };
    let fdev = frequency_deviation(event);
    let inputs: Vec<(&str, &[f64])> = vec![("|V|", &r.v_mag_pu), ("frequency", &fdev)];
    let mut signals = vec![];
    let col = |n: &str| traces.get(n).map(|c| c.to_vec());
    let mut add = |name: &str, sim: Option<Vec<f64>>, meas: &[f64]| {
        if let Some(s) = sim {
            let res: Vec<f64> = s.iter().zip(meas).map(|(a, b)| a - b).collect();
            signals.push(evidence::analyse(
                name, &r.time_s, &res, meas, &inputs, &opts,
            ));
        }
    };
    add("P", col("p_pu"), &r.p_pu);
    add("Q", col("q_pu"), &r.q_pu);
    if let Some(efd) = &r.efd_pu {
        add("Efd", col("efd"), efd);
    }
    if let Some(ifd) = &r.ifd_pu {
        add("Ifd", col("xadifd"), ifd);
    }
    let p_peak = traces.get("p_pu").and_then(|sim| {
        let res: Vec<f64> = sim.iter().zip(&r.p_pu).map(|(a, b)| a - b).collect();
        let n = r.time_s.len();
        let dt = (r.time_s[n - 1] - r.time_s[0]) / (n.max(2) - 1) as f64;
        evidence::spectral_peak(
            &res,
            dt,
            SHAFT_BAND_HZ.0,
            SHAFT_BAND_HZ.1.min(0.95 * 0.5 / dt),
        )
    });
    EventEvidence {
        event: event.name.clone(),
        onset_s: onset,
        signals,
        p_peak,
    }
}

/// Noise σ of a residual series: its standard deviation over the pre-event segment, where a
/// right model is in steady state (the difference-based floor of the whole record when the
/// pre-event is too short). Taken on the residual rather than the measurement, it also holds the
/// noise of the played-back voltage propagated through the model, white or not.
fn pre_event_noise(event: &Event, y: &[f64]) -> f64 {
    let (onset, _) = windows(event);
    let pre: Vec<f64> = event
        .record
        .time_s
        .iter()
        .zip(y)
        .filter(|(t, _)| **t < onset)
        .map(|(_, v)| *v)
        .collect();
    let s = if pre.len() >= 10 {
        std_dev(&pre)
    } else {
        evidence::noise_floor(y)
    };
    s.max(1e-6)
}

/// Standard deviation about the mean.
fn std_dev(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let m = y.iter().sum::<f64>() / n;
    (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt()
}

/// A surrogate of `event`: P and Q simulated by the reference (`traces`) on the measured input,
/// plus fresh white noise at the record's own noise levels (difference-based floors of the
/// pre-event P, Q, |V| and angle), the input channels getting theirs too.
fn surrogate(event: &Event, traces: &Traces, seed: u64) -> Result<Event, String> {
    let r = &event.record;
    let (onset, _) = windows(event);
    let pre = |y: &[f64]| {
        let v: Vec<f64> = r
            .time_s
            .iter()
            .zip(y)
            .filter(|(t, _)| **t < onset)
            .map(|(_, v)| *v)
            .collect();
        if v.len() >= 10 {
            evidence::noise_floor(&v)
        } else {
            evidence::noise_floor(y)
        }
    };
    let (sp, sq, sv, sa) = (
        pre(&r.p_pu),
        pre(&r.q_pu),
        pre(&r.v_mag_pu),
        pre(&r.v_ang_rad),
    );
    let (p, q) = (
        traces.get("p_pu").ok_or("no simulated P")?,
        traces.get("q_pu").ok_or("no simulated Q")?,
    );
    let mut rng = itaipu_dynamics::synthetic::Normal::new(seed ^ 0x005E_ED0F_5A11);
    let mut rec = r.clone();
    for k in 0..rec.time_s.len() {
        rec.p_pu[k] = p[k] + sp * rng.sample();
        rec.q_pu[k] = q[k] + sq * rng.sample();
        rec.v_mag_pu[k] += sv * rng.sample();
        rec.v_ang_rad[k] += sa * rng.sample();
    }
    Event::from_record(
        &format!("{} (surrogate)", event.name),
        rec,
        event.system_mva,
        event.nominal_hz,
        Some(event.init),
        Some(event.fit),
    )
    .map_err(|e| e.to_string())
}

/// A candidate's re-fit with the bounds and ties it was re-fitted over (for its standard errors).
type RefitRecord = (Refit, Vec<FreeBound>, Vec<(String, String)>);

/// Fit and held-out problem data.
struct Split {
    fit: Vec<EventData>,
    held: Vec<EventData>,
    description: String,
}

fn split(events: &[Event], held_out: &[Event], block_s: f64) -> Result<Split, DiagnoseError> {
    let data = |e: &Event| EventData::new(e, None, None).map_err(DiagnoseError::Setup);
    if !held_out.is_empty() {
        return Ok(Split {
            fit: events.iter().map(data).collect::<Result<_, _>>()?,
            held: held_out.iter().map(data).collect::<Result<_, _>>()?,
            description: format!(
                "fitted on {} event(s), judged on {} held-out event(s)",
                events.len(),
                held_out.len()
            ),
        });
    }
    let (mut fit, mut held) = (vec![], vec![]);
    for e in events {
        let d = data(e)?;
        let t0 = disturbance_s(e).map_or(e.record.time_s[0], |a| a - DISTURBANCE_LEAD_S);
        let even: Vec<bool> = e
            .record
            .time_s
            .iter()
            .map(|t| (((t - t0) / block_s).floor() as i64) % 2 == 0)
            .collect();
        let mut f = d.clone();
        let mut h = d;
        for ((fw, hw), e) in f
            .in_window
            .iter_mut()
            .zip(h.in_window.iter_mut())
            .zip(&even)
        {
            *fw &= *e;
            *hw &= !*e;
        }
        fit.push(f);
        held.push(h);
    }
    Ok(Split {
        fit,
        held,
        description: format!(
            "alternate {block_s} s blocks of each event, one fitted block starting \
             {DISTURBANCE_LEAD_S} s before the disturbance: even blocks fitted, odd blocks held out"
        ),
    })
}

/// How far before the disturbance the fitted block that holds it starts [s].
const DISTURBANCE_LEAD_S: f64 = 0.1;

/// When the event's disturbance starts: the first sample after the init window whose |V|
/// departs from the init window's mean by at least half the largest departure (`None` when
/// the largest departure is within 1 % of |V|: no disturbance to speak of, ambient data).
///
/// The fit/held-out split aligns its blocks on it, so that the few samples of a fault dip —
/// the ones that say most about the fast dynamics, and about what limits and saturation do —
/// are fitted rather than left to be predicted by a re-fit that never saw them: with blocks
/// counted from the start of the record, a 0.1 s dip falls in a held-out block as often as not.
fn disturbance_s(event: &Event) -> Option<f64> {
    let r = &event.record;
    let (n_pre, pre) = pre_event_v(event);
    let after = || r.time_s.iter().zip(&r.v_mag_pu).skip(n_pre);
    let max_dev = after().map(|(_, v)| (v - pre).abs()).fold(0.0, f64::max);
    if !(max_dev > 0.01 * pre.abs()) {
        return None;
    }
    after()
        .find(|(_, v)| (*v - pre).abs() >= 0.5 * max_dev)
        .map(|(t, _)| *t)
}

/// Largest RK4 step of the re-fits' L-BFGS phase [s] (a calibration uses 2 ms). Every re-fit's
/// χ² is taken with the accurate integrator, so the local phase only has to lead downhill; at
/// 5 ms (still at most half the smallest time constant) the re-fits of the whole catalog on a
/// clean 20 s dip end within 0.3 of the χ² they reach at 2 ms, in 40 % less time.
const REFIT_RK4_STEP_MAX_S: f64 = 5e-3;

/// Largest grid product scanned jointly (simulations) before falling back to one-at-a-time
/// scans.
const MAX_JOINT_SCAN: usize = 200;

/// Identifies a set of free parameters (for re-using a baseline re-fit).
fn bounds_key(bounds: &[FreeBound]) -> String {
    bounds
        .iter()
        .map(|b| format!("{}[{},{}]", b.param, b.min, b.max))
        .collect::<Vec<_>>()
        .join(";")
}

/// Outcome of one re-fit.
struct Refit {
    values: Vec<f64>,
    unit: Unit,
    chi2_fit: f64,
    chi2_held: f64,
    n_fit: usize,
    n_held: usize,
    simulations: usize,
    failures: usize,
    /// Variance inflation of the fitted residual, `(1 + ρ₁)/(1 − ρ₁)` (AR(1) approximation).
    vif: f64,
}

/// The scores of a re-fit (without its unit and values).
#[derive(Clone, Copy)]
struct Scores {
    chi2_fit: f64,
    chi2_held: f64,
    vif: f64,
}

impl Refit {
    fn clone_scores(&self) -> Scores {
        Scores {
            chi2_fit: self.chi2_fit,
            chi2_held: self.chi2_held,
            vif: self.vif,
        }
    }
}

/// `(1 + ρ₁)/(1 − ρ₁)` from the lag-1 autocorrelation of the P and Q residual series
/// (interleaved in `r`), ρ₁ clamped to [0, 0.9]: how much a χ² difference overstates the
/// evidence when the residual is not white.
fn variance_inflation(r: &[f64], channels: usize) -> f64 {
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

fn resolve(unit: &Unit, bounds: &[FreeBound]) -> Result<Vec<FreeParam>, String> {
    bounds
        .iter()
        .map(|b| {
            let r = unit.param(&b.param).map_err(|e| e.to_string())?;
            Ok(FreeParam::new(
                unit.param_path(r),
                r,
                b.min,
                b.max,
                b.start,
                unit.param_spec(r).unit,
            )
            .with_prior(b.prior))
        })
        .collect()
}

/// Grid scan of the parameters `scans` (`(index in problem.free, points)`) from the problem's
/// start: jointly on their grid product when it is small (limits and time constants that trade
/// against each other along a curved valley), otherwise one at a time with the others at their
/// start. The best grid point becomes the start when it improves on it.
fn scan(problem: &mut Problem, scans: &[(usize, usize)]) {
    let sim = search_integrator();
    let scanned: Vec<(usize, Vec<f64>)> = scans
        .iter()
        .map(|&(jj, n)| {
            let f = &problem.free[jj];
            (
                jj,
                (0..n)
                    .map(|i| f.from_unit(i as f64 / (n - 1) as f64))
                    .collect(),
            )
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
        let start_cost = problem.cost(&base, &sim);
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
        let (c, i) = problem.best_of(&points, &sim);
        if c < start_cost {
            for (jj, _) in &group {
                problem.free[*jj].start = points[i][*jj];
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn refit(
    unit: &Unit,
    bounds: &[FreeBound],
    ties: &[(String, String)],
    sp: &Split,
    weights: (f64, f64),
    opts: &DiagnoseOptions,
    label: &str,
    progress: &dyn Progress,
) -> Result<Refit, String> {
    if opts.cancelled() {
        return Err("interrupted".into());
    }
    let free = resolve(unit, bounds)?;
    let tie_refs = tie_refs(unit, ties)?;
    let fit_opts = FitOptions {
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
    };
    let mut x: Vec<f64> = free.iter().map(|f| f.start).collect();
    let mut simulations = 0;
    let mut failures = 0;

    // Phase 1: the global search (scan, swarm, L-BFGS) over the parameters that are not
    // polish-only, the others held at their start.
    let global: Vec<usize> = (0..bounds.len())
        .filter(|&j| !bounds[j].polish_only)
        .collect();
    if !global.is_empty() {
        let mut held_unit = unit.clone();
        for f in &free {
            held_unit.set(f.r, f.start);
        }
        let mut problem = Problem::new(
            held_unit,
            global.iter().map(|&j| free[j].clone()).collect(),
            sp.fit.clone(),
            weights,
        );
        problem.ties = tie_refs.clone();
        problem.prior_weight = PRIOR_WEIGHT;
        problem.cancel = opts.cancel.clone();
        // Scan (the parameters that ask for it), swarm, scan again from the swarm's best (the
        // interacting parameters it corrected move the valleys the scanned ones lie in), L-BFGS.
        let scans: Vec<(usize, usize)> = global
            .iter()
            .enumerate()
            .filter(|(_, &j)| bounds[j].scan >= 2)
            .map(|(jj, &j)| (jj, bounds[j].scan))
            .collect();
        scan(&mut problem, &scans);
        let swarm_only = FitOptions {
            lbfgs_iterations: 0,
            ..fit_opts.clone()
        };
        let best = search(&problem, &swarm_only, label, progress, true, &[]).0;
        for (f, v) in problem.free.iter_mut().zip(&best) {
            f.start = *v;
        }
        if !scans.is_empty() {
            scan(&mut problem, &scans);
        }
        let best = search(&problem, &fit_opts, label, progress, false, &[]).0;
        for (jj, &j) in global.iter().enumerate() {
            x[j] = best[jj];
        }
        simulations += problem.simulations();
        failures += problem.failures();
    }

    // Phase 2: L-BFGS over everything from there, when some parameters are polish-only.
    if global.len() < bounds.len() {
        let polish_free: Vec<FreeParam> = free
            .iter()
            .zip(&x)
            .map(|(f, v)| FreeParam {
                start: *v,
                ..f.clone()
            })
            .collect();
        let mut problem = Problem::new(unit.clone(), polish_free, sp.fit.clone(), weights);
        problem.ties = tie_refs.clone();
        problem.prior_weight = PRIOR_WEIGHT;
        problem.cancel = opts.cancel.clone();
        x = search(
            &problem,
            &fit_opts,
            &format!("{label} (polish)"),
            progress,
            false,
            &[],
        )
        .0;
        simulations += problem.simulations();
        failures += problem.failures();
    }

    if opts.cancelled() {
        return Err("interrupted".into());
    }
    let acc = accurate_integrator();
    let mut fit_problem = Problem::new(unit.clone(), free.clone(), sp.fit.clone(), weights);
    fit_problem.ties = tie_refs.clone();
    fit_problem.prior_weight = PRIOR_WEIGHT;
    let r_fit = fit_problem.residuals(&x, &acc)?;
    let mut held = Problem::new(unit.clone(), free, sp.held.clone(), weights);
    held.ties = tie_refs;
    let r_held = held.residuals(&x, &acc)?;
    Ok(Refit {
        unit: fit_problem.unit_at(&x),
        values: x,
        chi2_fit: sum_of_squares(&r_fit),
        chi2_held: sum_of_squares(&r_held),
        n_fit: r_fit.len(),
        n_held: r_held.len(),
        simulations,
        failures,
        vif: variance_inflation(
            &r_fit,
            if weights.0 > 0.0 && weights.1 > 0.0 {
                2
            } else {
                1
            },
        ),
    })
}

/// Standard errors of the re-fitted parameters `bounds` at `values` of `unit` (already at
/// those values), over every sample of `events`, with the priors' rows: `σ² (JᵀJ)⁻¹` by
/// [`crate::identify::analyse`]. `None` when a perturbed unit does not simulate.
fn std_errors(
    unit: &Unit,
    bounds: &[FreeBound],
    ties: &[(String, String)],
    values: &[f64],
    events: &[Event],
    weights: (f64, f64),
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
    let mut problem = Problem::new(unit.clone(), free, data, weights);
    problem.ties = tie_refs(unit, ties).ok()?;
    problem.prior_weight = PRIOR_WEIGHT;
    let jac = crate::fit::jacobian(&problem, values)?;
    let rss = sum_of_squares(&problem.residuals(values, &accurate_integrator()).ok()?);
    Some(crate::identify::analyse(&jac, rss, crate::fit::CORRELATION_LIMIT).std_errors)
}

/// The parameters of `ties` (`(from, to)` paths) in `unit`.
fn tie_refs(unit: &Unit, ties: &[(String, String)]) -> Result<Vec<(ParamRef, ParamRef)>, String> {
    ties.iter()
        .map(|(a, b)| {
            Ok((
                unit.param(a).map_err(|e| e.to_string())?,
                unit.param(b).map_err(|e| e.to_string())?,
            ))
        })
        .collect()
}

/// RMS of P and Q over every sample of the events (accurate integrator).
fn rms_pq(unit: &Unit, events: &[Event]) -> (f64, f64) {
    let (mut sp, mut sq, mut n) = (0.0, 0.0, 0.0);
    for e in events {
        if let Ok((f, _)) = fitness(unit, e, false) {
            sp += f.rms_p.powi(2) * f.samples as f64;
            sq += f.rms_q.powi(2) * f.samples as f64;
            n += f.samples as f64;
        }
    }
    ((sp / n.max(1.0)).sqrt(), (sq / n.max(1.0)).sqrt())
}

/// The dominant oscillatory mode above 1 Hz in the P residuals (matrix pencil), if any.
fn mode_hint(ev: &[EventEvidence], rate_hz: f64) -> Option<f64> {
    ev.iter()
        .flat_map(|e| e.signals.iter().filter(|s| s.signal == "P"))
        .flat_map(|s| s.modes.iter())
        .filter(|m| {
            m.freq_hz > 1.0
                && m.freq_hz < 0.45 * rate_hz
                && m.damping_ratio > -0.05
                && m.damping_ratio < 0.5
        })
        .max_by(|a, b| a.amplitude.total_cmp(&b.amplitude))
        .map(|m| m.freq_hz)
}

/// Weight of the priors' residuals in a re-fit: the re-fits' residuals are already in units of
/// the noise (weights 1/σ²), so a prior residual `ln(x/x₀)/spread` counts as one standardised
/// sample and the fitted χ² is the negative log-posterior (times 2).
const PRIOR_WEIGHT: f64 = 1.0;

/// The whole calibrated set of a fit as [`DiagnoseOptions::refit`] bounds: every parameter the
/// spec's `stages` free, within the spec's bounds, starting at its calibrated value in
/// `calibrated`, with the calibration's prior around its value in `datasheet` (the unit before
/// the fit). Re-fitting every extension and its baseline over this set with the same prior is
/// what lets the diagnosis see an effect the calibration absorbed by bending right values.
pub fn calibrated_set(
    spec: &crate::spec::CalibSpec,
    stages: &[String],
    datasheet: &Unit,
    calibrated: &Unit,
) -> Vec<FreeBound> {
    let mut out: Vec<FreeBound> = vec![];
    for st in spec.stages.iter().filter(|s| stages.contains(&s.name)) {
        for f in &st.free {
            let Ok(r) = calibrated.param(&f.param) else {
                continue;
            };
            let param = calibrated.param_path(r);
            if out.iter().any(|b| b.param == param) {
                continue;
            }
            let spread = f.spread.unwrap_or(spec.prior);
            let prior = datasheet
                .param(&param)
                .ok()
                .map(|d| crate::problem::Prior {
                    center: datasheet.get(d),
                    spread,
                })
                .filter(|p| p.spread > 0.0 && p.center > 0.0);
            out.push(FreeBound {
                param,
                min: f.min,
                max: f.max,
                start: calibrated.get(r).clamp(f.min, f.max),
                scan: 0,
                polish_only: true,
                prior,
            });
        }
    }
    out
}

/// A calibrated parameter to free again in every re-fit: its path (`machine.h`) and optional
/// `(min, max)` bounds (default: the model's declared range).
pub type RefitRequest = (String, Option<(f64, f64)>);

/// The [`DiagnoseOptions::refit`] bounds for calibrated parameters of `unit` named by path
/// (`machine.h`), each within the given `(min, max)` or, without, the model's declared range
/// widened to hold the current value. Errors name the parameter: unknown, bounds upside down
/// or empty, NaN.
pub fn refit_bounds(
    unit: &Unit,
    requested: &[RefitRequest],
) -> Result<Vec<FreeBound>, DiagnoseError> {
    let mut out: Vec<FreeBound> = vec![];
    for (path, range) in requested {
        let r = unit.param(path).map_err(|e| refit_error(path, e))?;
        let v = unit.get(r);
        let (min, max) = range.unwrap_or_else(|| {
            let (lo, hi) = unit.param_spec(r).range;
            (lo.min(v), hi.max(v))
        });
        let param = unit.param_path(r);
        if !out.iter().any(|b| b.param == param) {
            out.push(FreeBound {
                param,
                min,
                max,
                start: v,
                scan: 0,
                polish_only: true,
                prior: None,
            });
        }
    }
    check_refit(unit, &out)?;
    for b in &mut out {
        b.start = b.start.clamp(b.min, b.max);
    }
    Ok(out)
}

fn refit_error(path: &str, why: impl std::fmt::Display) -> DiagnoseError {
    DiagnoseError::Setup(format!("refit parameter {path}: {why}"))
}

/// Checks [`DiagnoseOptions::refit`]: every parameter exists in `unit` and its bounds are not
/// upside down, empty or NaN.
fn check_refit(unit: &Unit, refit: &[FreeBound]) -> Result<(), DiagnoseError> {
    for b in refit {
        unit.param(&b.param).map_err(|e| refit_error(&b.param, e))?;
        if !(b.min < b.max) {
            return Err(refit_error(
                &b.param,
                format!("bounds [{}, {}] are upside down or empty", b.min, b.max),
            ));
        }
    }
    Ok(())
}

/// The catalog context of `unit` on `event` (operating-point field voltage and current, PMU
/// rate), without evidence hints. Used to hide a cause in a synthetic truth.
pub fn context(unit: &Unit, event: &Event) -> Result<Context, String> {
    let (_, tr) = fitness(unit, event, false)?;
    Ok(context_from(&tr, event))
}

/// The catalog context read from a unit's traces on `event` (no evidence hints).
fn context_from(traces: &Traces, event: &Event) -> Context {
    let t = &event.record.time_s;
    Context {
        efd0: traces.get("efd").map(|c| c[0]),
        xadifd0: traces.get("xadifd").map(|c| c[0]),
        rate_hz: (t.len() - 1) as f64 / (t[t.len() - 1] - t[0]),
        ..Default::default()
    }
}

/// Diagnoses `unit` (normally already calibrated) on `events`, judging candidates on `held_out`
/// events when given (see the module documentation).
pub fn diagnose(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseResult, DiagnoseError> {
    let result = diagnose_run(unit, events, held_out, opts, progress);
    // A re-fit cut short reads as a failed candidate: never hand out a verdict built on one.
    match result {
        Ok(r) => {
            interrupted(opts, &r.report.candidates)?;
            Ok(r)
        }
        Err(_) if opts.cancelled() => Err(DiagnoseError::Interrupted { tried: vec![] }),
        Err(e) => Err(e),
    }
}

/// [`DiagnoseError::Interrupted`] when [`DiagnoseOptions::cancel`] is set, naming the causes
/// tried (`done`).
fn interrupted(opts: &DiagnoseOptions, done: &[CandidateReport]) -> Result<(), DiagnoseError> {
    if !opts.cancelled() {
        return Ok(());
    }
    Err(DiagnoseError::Interrupted {
        tried: done.iter().map(|c| c.cause.clone()).collect(),
    })
}

fn diagnose_run(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseResult, DiagnoseError> {
    let t_start = Instant::now();
    if events.is_empty() {
        return Err(DiagnoseError::Setup("no event to diagnose".into()));
    }
    for c in &opts.causes {
        if !user_cause::known(c, &opts.user_causes) {
            return Err(DiagnoseError::Setup(format!(
                "unknown cause '{c}' (known: {})",
                user_cause::ids(&opts.user_causes)
            )));
        }
    }
    check_refit(unit, &opts.refit)?;
    if !(opts.block_s > 0.0) {
        return Err(DiagnoseError::Setup(format!(
            "block length must be > 0 s (got {})",
            opts.block_s
        )));
    }

    // 1. Noise, from the pre-event residual of the unit as given.
    let mut given = vec![];
    for e in events {
        let (_, tr) = fitness(unit, e, false).map_err(|msg| DiagnoseError::Simulation {
            event: e.name.clone(),
            msg,
        })?;
        given.push(tr);
    }
    let n_all: f64 = events.iter().map(|e| e.record.time_s.len() as f64).sum();
    let residual = |k: usize, sim: &str, meas: &[f64]| -> Vec<f64> {
        given[k]
            .get(sim)
            .map(|s| s.iter().zip(meas).map(|(a, b)| a - b).collect())
            .unwrap_or_default()
    };
    let sigma = |sim: &str, pick: fn(&Event) -> &[f64]| {
        let v: Vec<f64> = events
            .iter()
            .enumerate()
            .map(|(k, e)| pre_event_noise(e, &residual(k, sim, pick(e))))
            .collect();
        (events
            .iter()
            .zip(&v)
            .map(|(e, s)| s * s * e.record.time_s.len() as f64)
            .sum::<f64>()
            / n_all)
            .sqrt()
    };
    let sigma_p = sigma("p_pu", |e| &e.record.p_pu);
    let sigma_q = sigma("q_pu", |e| &e.record.q_pu);
    let weights = (1.0 / sigma_p.powi(2), 1.0 / sigma_q.powi(2));
    let sp = split(events, held_out, opts.block_s)?;

    // 2. The reference: the unit with its set-point offsets (nuisance) re-fitted; the evidence
    //    and the verdict are about what it still gets wrong.
    let nuisance = catalog::nuisance(unit);
    let reference = refit(
        unit,
        &nuisance,
        &[],
        &sp,
        weights,
        opts,
        "nuisance offsets",
        progress,
    )
    .map_err(|msg| DiagnoseError::Simulation {
        event: events[0].name.clone(),
        msg,
    })?;
    let mut before = vec![];
    let mut evidence_before = vec![];
    for e in events {
        let (_, tr) =
            fitness(&reference.unit, e, false).map_err(|msg| DiagnoseError::Simulation {
                event: e.name.clone(),
                msg,
            })?;
        evidence_before.push(event_evidence(e, &tr));
        before.push((e.name.clone(), tr));
    }
    // Surrogate events: what the reference unit would give on these inputs, with measurement
    // noise on P, Q and input noise on |V| and the angle drawn again at the levels the record
    // shows. The reference is exact there, so a re-fit's gain on them is pure noise fitting.
    let mut surrogate_held = vec![];
    for (k, e) in held_out.iter().enumerate() {
        let (_, tr) =
            fitness(&reference.unit, e, true).map_err(|msg| DiagnoseError::Simulation {
                event: e.name.clone(),
                msg,
            })?;
        surrogate_held.push(
            surrogate(e, &tr, opts.seed.wrapping_add(1000 + k as u64))
                .map_err(DiagnoseError::Setup)?,
        );
    }
    let surrogate_events: Vec<Event> = events
        .iter()
        .zip(&before)
        .enumerate()
        .map(|(k, (e, (_, tr)))| surrogate(e, tr, opts.seed.wrapping_add(k as u64)))
        .collect::<Result<_, _>>()
        .map_err(DiagnoseError::Setup)?;
    let sp_null = split(&surrogate_events, &surrogate_held, opts.block_s)?;
    let unit = &reference.unit.clone();
    let mut baselines: BTreeMap<String, Refit> = BTreeMap::new();
    baselines.insert(bounds_key(&nuisance), reference);

    // 3. Context for the catalog.
    let mut ctx = context_from(&before[0].1, &events[0]);
    ctx.mode_hint_hz = mode_hint(&evidence_before, ctx.rate_hz);
    ctx.shaft_resonance = evidence_before
        .iter()
        .filter_map(|e| e.p_peak.clone())
        .filter(catalog::resonance_stands_out)
        .min_by(|a, b| a.p_value.total_cmp(&b.p_value));
    let (dip, df) = regime(events);
    (ctx.deepest_dip, ctx.sustained_df_hz) = (Some(dip), Some(df));
    ctx.field_current_rise = before
        .iter()
        .filter_map(|(_, tr)| {
            let i = tr.get("xadifd")?;
            let i0 = *i.first()?;
            (i0 > 0.0).then(|| i.iter().copied().fold(i0, f64::max) / i0 - 1.0)
        })
        .reduce(f64::max);

    // 4. Candidates.
    let ids: Vec<&str> = if opts.causes.is_empty() {
        let users = opts.user_causes.iter().map(|u| u.id.as_str());
        CAUSES.iter().map(|c| c.info().id).chain(users).collect()
    } else {
        opts.causes.iter().map(|s| s.as_str()).collect()
    };
    let mut reports = vec![];
    let mut refits: BTreeMap<String, RefitRecord> = BTreeMap::new();
    for id in ids {
        interrupted(opts, &reports)?;
        // A catalog cause (its evidence rules and signature), or a user cause (none).
        let cause = catalog::cause(id);
        let (title, extension) = user_cause::describe(id, &opts.user_causes).expect("checked");
        let t0 = Instant::now();
        let mut rep = CandidateReport {
            cause: id.to_string(),
            title,
            applicable: false,
            note: String::new(),
            extension,
            parameters: vec![],
            fixed: vec![],
            gains: None,
            significant: false,
            signature: cause.map_or_else(Vec::new, |c| c.signature(&evidence_before, &ctx)),
            simulations: 0,
            failed_candidates: 0,
            wall_s: 0.0,
            distortion: vec![],
        };
        let ext: Extension = match user_cause::extend(id, unit, &ctx, &opts.user_causes) {
            Err(catalog::CauseError::NotApplicable(why)) => {
                rep.note = format!("not applicable: {why}");
                reports.push(rep);
                continue;
            }
            Err(e) => {
                rep.note = format!("could not build the extension: {e}");
                reports.push(rep);
                continue;
            }
            Ok(ext) => ext,
        };
        let mut ext = ext;
        for b in &opts.refit {
            let known = ext
                .extension_free
                .iter()
                .chain(&ext.interacting_free)
                .any(|f| f.param == b.param);
            if known {
                // A cause's own interacting parameter keeps its bounds and takes the prior.
                for f in ext
                    .interacting_free
                    .iter_mut()
                    .filter(|f| f.param == b.param)
                {
                    f.prior = b.prior;
                }
            } else if ext.unit.param(&b.param).is_ok() {
                let v = ext
                    .unit
                    .param(&b.param)
                    .map(|r| ext.unit.get(r))
                    .unwrap_or(b.start);
                ext.interacting_free.push(FreeBound {
                    start: v.clamp(b.min, b.max),
                    polish_only: true,
                    ..b.clone()
                });
            }
        }
        rep.applicable = true;
        rep.extension = ext.description.clone();
        rep.fixed = ext.fixed.clone();
        progress.message(&format!("diagnose: {id}: {}", ext.description));

        // Baseline: the unit as given, re-fitted over the same interacting parameters.
        // (Only those the unit as given has: a replaced block's parameters are the extension's.)
        let base_bounds: Vec<FreeBound> = ext
            .interacting_free
            .iter()
            .filter_map(|b| {
                let start = unit.param(&b.param).map(|r| unit.get(r)).ok()?;
                Some(FreeBound {
                    start: start.clamp(b.min, b.max),
                    ..b.clone()
                })
            })
            .collect();
        let key = bounds_key(&base_bounds);
        if !baselines.contains_key(&key) {
            match refit(
                unit,
                &base_bounds,
                &[],
                &sp,
                weights,
                opts,
                &format!("{id} baseline"),
                progress,
            ) {
                Ok(r) => {
                    baselines.insert(key.clone(), r);
                }
                Err(msg) => {
                    rep.note = format!("the baseline re-fit failed: {msg}");
                    reports.push(rep);
                    continue;
                }
            }
        }
        // The extension's re-fit starts from the calibrated values (the extension may need the
        // interacting parameters back where the calibration found them); when it ends worse than
        // the baseline, it is run again from where the baseline ended, so that with the extension
        // at its neutral start it is at least the baseline.
        let mut bounds = ext.extension_free.clone();
        bounds.extend(ext.interacting_free.iter().cloned());
        let ext_opts = DiagnoseOptions {
            pso_iterations: opts.pso_iterations * ext.search_factor.max(1),
            ..opts.clone()
        };
        let base_opts = opts;
        let opts = &ext_opts;
        let mut r = match refit(
            &ext.unit, &bounds, &ext.ties, &sp, weights, opts, id, progress,
        ) {
            Ok(r) => r,
            Err(msg) => {
                rep.note =
                    format!("the extended unit does not simulate at the best candidate: {msg}");
                rep.wall_s = t0.elapsed().as_secs_f64();
                reports.push(rep);
                continue;
            }
        };
        if r.chi2_fit > baselines[&key].chi2_fit && !base_bounds.is_empty() {
            let from_base: Vec<FreeBound> = ext
                .extension_free
                .iter()
                .cloned()
                .chain(ext.interacting_free.iter().map(|b| {
                    let v = baselines[&key]
                        .unit
                        .param(&b.param)
                        .map(|p| baselines[&key].unit.get(p))
                        .unwrap_or(b.start);
                    FreeBound {
                        start: v.clamp(b.min, b.max),
                        ..b.clone()
                    }
                }))
                .collect();
            if let Ok(r2) = refit(
                &ext.unit,
                &from_base,
                &ext.ties,
                &sp,
                weights,
                opts,
                &format!("{id} from the baseline"),
                progress,
            ) {
                if r2.chi2_fit < r.chi2_fit {
                    r = Refit {
                        simulations: r.simulations + r2.simulations,
                        ..r2
                    };
                }
            }
        }
        let k = ext.extension_free.len() + ext.discrete_params;
        let n = r.n_fit.max(1) as f64;
        let bic = |d_fit: f64, vif: f64| d_fit / vif - k as f64 * (n / vif).max(1.0).ln();
        let passes = |d_fit: f64, d_held: f64, base: &Scores| {
            bic(d_fit, base.vif) > opts.bic_threshold
                && d_fit >= opts.min_fit_drop * base.chi2_fit
                && d_held >= opts.min_held_drop * base.chi2_held
        };
        // The baseline again from the interacting values the extension's re-fit found (the
        // extension's search may have found a better set-point than the baseline's own): the
        // baseline is the best over the same parameters, so no gain comes from optimisation luck.
        // Only for a gain that could pass: a better baseline only lowers it.
        let b = &baselines[&key];
        let could_pass = passes(
            b.chi2_fit - r.chi2_fit,
            b.chi2_held - r.chi2_held,
            &b.clone_scores(),
        );
        if !base_bounds.is_empty() && could_pass {
            let from_ext: Vec<FreeBound> = base_bounds
                .iter()
                .map(|b| {
                    let v = r
                        .unit
                        .param(&b.param)
                        .map(|p| r.unit.get(p))
                        .unwrap_or(b.start);
                    FreeBound {
                        start: v.clamp(b.min, b.max),
                        scan: 0,
                        ..b.clone()
                    }
                })
                .collect();
            let polish = DiagnoseOptions {
                pso_iterations: 0,
                ..opts.clone()
            };
            if let Ok(b2) = refit(
                unit,
                &from_ext,
                &[],
                &sp,
                weights,
                &polish,
                &format!("{id} baseline again"),
                progress,
            ) {
                if b2.chi2_fit < baselines[&key].chi2_fit {
                    baselines.insert(key.clone(), b2);
                }
            }
        }
        let base = baselines[&key].clone_scores();
        let raw_fit = base.chi2_fit - r.chi2_fit;
        let raw_held = base.chi2_held - r.chi2_held;
        let bic = |d_fit: f64| bic(d_fit, base.vif);
        let passes = |d_fit: f64, d_held: f64| passes(d_fit, d_held, &base);
        // The noise-fitting part of the gain, measured on the surrogate events (only for a
        // candidate whose raw gain could pass: the correction only lowers it).
        let (mut null_fit, mut null_held) = (0.0, 0.0);
        if passes(raw_fit, raw_held) {
            let nkey = format!("null:{key}");
            if !baselines.contains_key(&nkey) {
                if let Ok(b) = refit(
                    unit,
                    &base_bounds,
                    &[],
                    &sp_null,
                    weights,
                    base_opts,
                    &format!("{id} null baseline"),
                    progress,
                ) {
                    baselines.insert(nkey.clone(), b);
                }
            }
            // The standard search budget: on the surrogate the reference is exact and the
            // start is its optimum, so the longer search a bent calibration needs buys nothing.
            match (baselines.get(&nkey), refit(&ext.unit, &bounds, &ext.ties, &sp_null, weights, base_opts, &format!("{id} null"), progress)) {
                (Some(b0), Ok(r0)) => {
                    null_fit = (b0.chi2_fit - r0.chi2_fit).max(0.0);
                    null_held = (b0.chi2_held - r0.chi2_held).max(0.0);
                    rep.simulations += r0.simulations;
                }
                _ => rep.note = "the surrogate (noise-only) re-fit failed: the gain is not corrected for noise fitting".into(),
            }
        }
        let base = &baselines[&key];
        let (rms_p_base, rms_q_base) = rms_pq(&base.unit, events);
        let (rms_p_ext, rms_q_ext) = rms_pq(&r.unit, events);
        let (net_fit, net_held) = (raw_fit - null_fit, raw_held - null_held);
        let gains = Gains {
            chi2_fit_base: base.chi2_fit,
            chi2_fit_ext: r.chi2_fit,
            chi2_held_base: base.chi2_held,
            chi2_held_ext: r.chi2_held,
            null_gain_fit: null_fit,
            null_gain_held: null_held,
            fit_drop: net_fit / base.chi2_fit.max(1e-300),
            held_drop: net_held / base.chi2_held.max(1e-300),
            delta_bic: bic(net_fit),
            vif: base.vif,
            k,
            n_fit: r.n_fit,
            n_held: r.n_held,
            rms_p_base,
            rms_q_base,
            rms_p_ext,
            rms_q_ext,
        };
        rep.significant = passes(net_fit, net_held);
        let fitted: Vec<(String, f64)> = resolve(&ext.unit, &bounds)
            .unwrap_or_default()
            .iter()
            .zip(&r.values)
            .map(|(f, v)| (f.path.clone(), *v))
            .collect();
        if let Some(why) = cause.and_then(|c| c.below_resolution(&fitted, &ctx)) {
            if rep.significant {
                rep.significant = false;
                rep.note = format!("not named: {why}");
            }
        }
        if !rep.significant {
            if let Some(why) = cause.and_then(|c| c.named_by_evidence(&ctx)) {
                rep.significant = true;
                rep.note = format!("named by the evidence: {why}");
            }
        }
        rep.distortion = distortion(&opts.refit, &base.unit, &r.unit);
        let free = resolve(&ext.unit, &bounds).unwrap_or_default();
        rep.parameters = free
            .iter()
            .zip(&r.values)
            .enumerate()
            .map(|(i, (f, v))| CandidateParam {
                param: f.path.clone(),
                unit: f.unit.to_string(),
                start: f.start,
                min: f.lo,
                max: f.hi,
                result: *v,
                extension: i < ext.extension_free.len(),
                at_bound: f.at_bound(*v),
                std_error: None,
            })
            .collect();
        progress.message(&format!(
            "diagnose: {id}: χ² {:.1} -> {:.1} (fit), {:.1} -> {:.1} (held out), ΔBIC {:.1}{}",
            gains.chi2_fit_base,
            gains.chi2_fit_ext,
            gains.chi2_held_base,
            gains.chi2_held_ext,
            gains.delta_bic,
            if rep.significant { ", significant" } else { "" }
        ));
        rep.gains = Some(gains);
        rep.simulations += r.simulations + base.simulations;
        rep.failed_candidates = r.failures;
        rep.wall_s = t0.elapsed().as_secs_f64();
        refits.insert(id.to_string(), (r, bounds.clone(), ext.ties.clone()));
        reports.push(rep);
    }

    // 5. Rank and decide.
    // Significant candidates first. Each passed the test against its own baseline (the same
    // interacting parameters re-fitted without it); among them, the extended model that
    // explains the data best wins: lowest BIC on the common fitted samples,
    // χ²_ext + k ln N with k every parameter the candidate re-fitted (a cause whose extension
    // is only significant because its baseline stayed bent does not beat one that fits). The
    // others follow by ΔBIC.
    let bic_ext = |r: &CandidateReport| {
        r.gains.as_ref().map_or(f64::INFINITY, |g| {
            g.chi2_fit_ext + r.parameters.len() as f64 * (g.n_fit.max(1) as f64).ln()
        })
    };
    reports.sort_by(|a, b| {
        let s = |r: &CandidateReport| r.gains.as_ref().map_or(f64::NEG_INFINITY, |g| g.delta_bic);
        b.significant.cmp(&a.significant).then(if a.significant {
            bic_ext(a).total_cmp(&bic_ext(b))
        } else {
            s(b).total_cmp(&s(a))
        })
    });
    let named = reports.iter().find(|r| r.significant).cloned();
    let mut extended_unit = None;
    let mut after = vec![];
    let mut evidence_after = vec![];
    let verdict = match named {
        Some(mut rep) => {
            let (r, bounds, ties) = refits
                .remove(&rep.cause)
                .expect("a significant candidate was re-fitted");
            // Uncertainty of the re-fitted parameters (all samples, with the priors).
            if let Some(se) = std_errors(&r.unit, &bounds, &ties, &r.values, events, weights) {
                for (p, e) in rep.parameters.iter_mut().zip(se) {
                    p.std_error = Some(e);
                }
                if let Some(c) = reports.iter_mut().find(|c| c.cause == rep.cause) {
                    c.parameters = rep.parameters.clone();
                }
            }
            for e in events {
                if let Ok((_, tr)) = fitness(&r.unit, e, false) {
                    evidence_after.push(event_evidence(e, &tr));
                    after.push((e.name.clone(), tr));
                }
            }
            let mut key: Vec<(String, f64, String)> = rep
                .parameters
                .iter()
                .filter(|p| p.extension)
                .map(|p| (p.param.clone(), p.result, p.unit.clone()))
                .collect();
            key.extend(
                rep.fixed
                    .iter()
                    .map(|(p, v)| (p.clone(), *v, "-".to_string())),
            );
            let g = rep
                .gains
                .clone()
                .expect("significant candidates have gains");
            let params: Vec<String> = key
                .iter()
                .map(|(p, v, u)| {
                    let se = rep
                        .parameters
                        .iter()
                        .find(|c| &c.param == p)
                        .and_then(|c| c.std_error)
                        .filter(|e| e.is_finite())
                        .map_or(String::new(), |e| format!(" ± {}", fmt_num(e)));
                    format!("{p} = {}{se} {u}", fmt_num(*v))
                })
                .collect();
            let statement = format!(
                "{}: {}. The extension ({}) lowers χ² on the fitted samples by {:.0} % ({:.1} -> {:.1}) and on the held-out \
                 samples by {:.0} %; ΔBIC = {:.1} with {} added parameter(s). Fitted values: {}.",
                rep.cause,
                rep.title,
                rep.extension,
                100.0 * g.fit_drop,
                g.chi2_fit_base,
                g.chi2_fit_ext,
                100.0 * g.held_drop,
                g.delta_bic,
                g.k,
                params.join(", ")
            );
            // Which calibrated values become plausible again with it.
            let back: Vec<String> = rep
                .distortion
                .iter()
                .filter(|d| d.z_base.abs() > 1.0 && d.z_extended.abs() < d.z_base.abs())
                .map(|d| {
                    format!(
                        "{} {} -> {} (datasheet {})",
                        d.param,
                        fmt_num(d.base),
                        fmt_num(d.extended),
                        fmt_num(d.datasheet)
                    )
                })
                .collect();
            let statement = if back.is_empty() {
                statement
            } else {
                format!(
                    "{statement} Without it the re-fitted unit bends calibrated values away from their datasheet; with it they come back: {}.",
                    back.join(", ")
                )
            };
            extended_unit = Some(r.unit);
            Verdict {
                cause: rep.cause.clone(),
                title: rep.title.clone(),
                statement,
                key_parameters: key,
                gains: Some(g),
                where_: None,
            }
        }
        None => undecided(&evidence_before, &reports, opts, sigma_p, sigma_q),
    };

    let report = Diagnosis {
        unit: unit.name.clone(),
        events: events.iter().map(|e| e.name.clone()).collect(),
        held_out: held_out.iter().map(|e| e.name.clone()).collect(),
        verdict,
        candidates: reports,
        evidence: evidence_before,
        evidence_after,
        noise: NoiseModel {
            sigma_p,
            sigma_q,
            split: sp.description.clone(),
            n_fit: sp.fit.iter().map(|d| d.n_window()).sum(),
            n_held: sp.held.iter().map(|d| d.n_window()).sum(),
        },
        refit: opts.refit.clone(),
        seed: opts.seed,
        threads: rayon::current_num_threads(),
        wall_s: t_start.elapsed().as_secs_f64(),
    };
    Ok(DiagnoseResult {
        report,
        extended_unit,
        before,
        after,
    })
}

fn fmt_num(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

/// The verdict when no cause is significant: `none` at the noise floor, else `unexplained`
/// with where the residual lives.
fn undecided(
    ev: &[EventEvidence],
    reports: &[CandidateReport],
    opts: &DiagnoseOptions,
    sigma_p: f64,
    sigma_q: f64,
) -> Verdict {
    // The signal with the largest residual RMS relative to its noise σ.
    let ratio = |s: &SignalEvidence| s.rms / if s.signal == "P" { sigma_p } else { sigma_q };
    let mut worst: Option<(&str, &SignalEvidence)> = None;
    for e in ev {
        for s in e
            .signals
            .iter()
            .filter(|s| s.signal == "P" || s.signal == "Q")
        {
            if worst.is_none_or(|(_, w)| ratio(s) > ratio(w)) {
                worst = Some((&e.event, s));
            }
        }
    }
    let best_try = reports
        .iter()
        .filter_map(|r| r.gains.as_ref().map(|g| (r, g)))
        .next()
        .map(|(r, g)| {
            format!(
                " The best candidate, {}, gained ΔBIC {:.1} ({:.1} % of χ²), below the threshold.",
                r.cause,
                g.delta_bic,
                100.0 * g.fit_drop
            )
        })
        .unwrap_or_default();
    let Some((event, s)) = worst else {
        return Verdict {
            cause: "none".into(),
            title: "no residual to explain".into(),
            statement: "No P or Q residual.".into(),
            key_parameters: vec![],
            gains: None,
            where_: None,
        };
    };
    let top = s
        .windows
        .iter()
        .max_by(|a, b| a.share_of_sse.total_cmp(&b.share_of_sse));
    let where_ = top.map(|w| (s.signal.clone(), w.label.clone(), w.start_s, w.end_s));
    let over = ratio(s);
    if over <= opts.noise_factor {
        Verdict {
            cause: "none".into(),
            title: "residual at the noise floor".into(),
            statement: format!(
                "No cause named: the residuals are at the noise level (largest: {} on {event}, RMS {:.2} × the pre-event \
                 residual σ; Ljung-Box p = {:.2}) and no extension gains significantly.{best_try} The model needs no extension \
                 for these data.",
                s.signal, over, s.whiteness.p_value
            ),
            key_parameters: vec![],
            gains: None,
            where_,
        }
    } else {
        let w = top.expect("windows exist");
        let mode = s
            .modes
            .iter()
            .filter(|m| m.freq_hz > 0.1)
            .max_by(|a, b| a.energy_share.total_cmp(&b.energy_share))
            .map(|m| {
                format!(
                    ", dominant residual mode {:.2} Hz (ζ = {:.2})",
                    m.freq_hz, m.damping_ratio
                )
            })
            .unwrap_or_default();
        Verdict {
            cause: "unexplained".into(),
            title: format!("unexplained residual at {} ({}, {:.2}-{:.2} s)", s.signal, w.label, w.start_s, w.end_s),
            statement: format!(
                "Unexplained residual at {} in the {} window ({:.2}-{:.2} s, {:.0} % of its squared error) on {event}: RMS {:.2} × \
                 the pre-event residual σ, Ljung-Box p = {:.2}{mode}. No catalog extension explains it significantly.{best_try}",
                s.signal,
                w.label,
                w.start_s,
                w.end_s,
                100.0 * w.share_of_sse,
                over,
                s.whiteness.p_value
            ),
            key_parameters: vec![],
            gains: None,
            where_,
        }
    }
}
