//! What a diagnosis reports: the evidence, each candidate's re-fit and gains, the verdict, the
//! noise model and the profile (written as JSON by the command line, read by Python and the
//! fleet).

use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;
use serde::Serialize;

use crate::bounds::FreeBound;
use crate::evidence::{self, SignalEvidence};

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
    /// The part of both fitted χ² that the record played back as recorded adds
    /// ([`CandidateReport::input_as_recorded`]; 0 otherwise): the reference unit's fitted χ² as
    /// recorded less its χ² smoothed, the voltage noise's echo. Taken off `chi2_fit_ext` where
    /// candidates are compared with each other, so that each is compared on the smoothed
    /// playback's footing; its own test against its baseline (on the same input) keeps it.
    pub input_echo: f64,
    pub chi2_held_base: f64,
    pub chi2_held_ext: f64,
    /// The priors' rows in the baseline's and the extension's χ² (each of its fitted and
    /// held-out χ² holds them once): what the calibrated values' distance from their datasheet
    /// costs. A gain made of these rows alone is un-bending, not the data's evidence.
    pub chi2_prior_base: f64,
    pub chi2_prior_ext: f64,
    /// χ² drop of the residuals (the priors' rows left out) that the same re-fit achieves on
    /// the surrogate events, where the reference model is exact and only noise can be fitted
    /// (fitted and held-out samples).
    pub null_gain_fit: f64,
    pub null_gain_held: f64,
    /// The fitted samples' noise-fitting gain of each surrogate draw whose re-fits ran
    /// ([`super::DiagnoseOptions::null_draws`]; `null_gain_fit` is their mean); empty where no
    /// surrogate re-fit ran (a gain that could not pass).
    pub null_gains_fit: Vec<f64>,
    /// The held-out samples' noise-fitting gain of the same draws (`null_gain_held` is their
    /// mean).
    pub null_gains_held: Vec<f64>,
    /// Net relative drop on the fitted samples:
    /// `(chi2_fit_base − chi2_fit_ext − null_gain_fit)/chi2_fit_base`.
    pub fit_drop: f64,
    /// Net relative drop on the held-out samples, likewise.
    pub held_drop: f64,
    /// Relative held-out drop on the contiguous segments of the second held-out test, when it
    /// ran (an extension whose fitted gain passes and whose held-out blocks do not confirm it).
    pub held_drop_segments: Option<f64>,
    /// `Δχ²/VIF − k ln(N/VIF)` with the net `Δχ²`: the BIC difference with the χ² difference
    /// and the sample size deflated by the baseline residual's variance inflation (positive
    /// favours the extension).
    pub delta_bic: f64,
    /// The whole record's evidence, `2 ln B`: `delta_bic` plus the held-out samples' predictive
    /// gain `Δχ²_held/VIF` (net), what significance is judged on
    /// ([`super::gain::record_evidence`]).
    pub record_evidence: f64,
    /// Variance inflation factor of the baseline residual (1 for white noise).
    pub vif: f64,
    /// Parameters counted (the extension's, plus discrete switches).
    pub k: usize,
    pub n_fit: usize,
    pub n_held: usize,
    /// RMS of each compared channel over all samples, `(signal, baseline, extended)` [pu]
    /// (P and Q in the phasor playback, on the system base).
    pub rms: Vec<(String, f64, f64)>,
    /// RMS of P and Q over all samples, before (baseline) and after [pu system base] (`null`
    /// when the playback does not compare them).
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
    /// Its gain passed the statistical test (the fitted and held-out drops and the record's
    /// evidence, as step 6 states them), whatever the physical checks then said. One that
    /// passed and is not `significant` was refused by them (`note`: a fitted value no unit of
    /// its cause has, an extension pressed against its range, a minority of the misfit): the
    /// record holds an effect at least as large as the test can tell from noise, which this
    /// cause is not.
    pub passed_test: bool,
    /// A bundled effect outside the catalog ([`super::look_alike`]): tried against the others, never
    /// named.
    pub look_alike: bool,
    /// Significant by the cause's signature in the evidence (e.g. a shaft resonance's peak),
    /// not by the re-fit's test: never graded `strong`.
    pub by_evidence: bool,
    /// What in the evidence points to (or away from) this cause.
    pub signature: Vec<String>,
    pub simulations: usize,
    pub failed_candidates: usize,
    pub wall_s: f64,
    /// The calibrated parameters (with a datasheet prior) that the baseline holds more than one
    /// prior spread from their datasheet value, or that the extension does: what the base model
    /// bends to mimic the cause, and where they go with the extension.
    pub distortion: Vec<Distortion>,
    /// Its re-fits (baseline, extension, surrogates) played the record's |V| and angle back as
    /// recorded, not low-passed: the cause adds a mode above the input's cut-off
    /// ([`super::catalog::Cause::band_top_hz`]).
    pub input_as_recorded: bool,
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

/// The verdict.
#[derive(Debug, Clone, Serialize)]
pub struct Verdict {
    /// The cause named, or why none is ([`VerdictCause`]; written as its id or `none`,
    /// `unexplained`, `inconclusive`).
    pub cause: VerdictCause,
    pub title: String,
    /// One paragraph for a person.
    pub statement: String,
    /// The named cause's key parameters `(path, value, unit)`.
    pub key_parameters: Vec<(String, f64, String)>,
    pub gains: Option<Gains>,
    /// Where the residual lives: `(signal, window, start_s, end_s)`.
    #[serde(rename = "where")]
    pub where_: Option<(String, String, f64, f64)>,
    /// A named cause's confidence: `strong` or `moderate` (see [`Grade`]); `None` for `none`,
    /// `unexplained` and `inconclusive`.
    pub grade: Option<Grade>,
    /// The named cause's approximate posterior probability among the models compared (its
    /// re-fitted baseline and the other significant candidates' extensions, equal prior odds),
    /// from their VIF-deflated BIC: `1 / Σ_m exp(−(BIC_m − BIC_named)/2)`.
    pub probability: Option<f64>,
    /// The named cause's confidence: the probability's parts and the grade's reasons.
    pub confidence: Option<Confidence>,
    /// `inconclusive`: the significant candidates that explain the residual about equally
    /// (the best first), each with its VIF-deflated BIC above the best's.
    pub competing: Vec<(String, f64)>,
}

/// What a verdict says: a cause named (of the catalog, or of the user's cause files), or why
/// none is. Written in reports as the cause's id or one of [`NO_CAUSE_VERDICTS`], the strings
/// the JSON reports, the Python module and the fleet read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum VerdictCause {
    /// A cause of the catalog ([`super::catalog::CAUSES`]), by its id.
    Catalog(&'static str),
    /// A cause from a cause file ([`super::user_cause`]), by its id.
    User(String),
    /// No cause: the residuals are at the noise floor and no extension gains significantly.
    None,
    /// A residual no cause of the catalog or of the user's explains (or one a look-alike outside
    /// the catalog explains best, or one whose best explanation the physical checks refused).
    Unexplained,
    /// Several causes explain the residual about equally, or the fitted and held-out samples
    /// disagree on which does.
    Inconclusive,
}

/// The verdicts that name no cause: `none` (at the noise floor), `unexplained` (a residual no
/// candidate explains) and `inconclusive` (several explain it about equally). A user cause may
/// not take one of these ids.
pub const NO_CAUSE_VERDICTS: [&str; 3] = ["none", "unexplained", "inconclusive"];

impl VerdictCause {
    /// The id as reports write it: the cause's, or `none`, `unexplained`, `inconclusive`.
    pub fn as_str(&self) -> &str {
        match self {
            VerdictCause::Catalog(id) => id,
            VerdictCause::User(id) => id,
            VerdictCause::None => NO_CAUSE_VERDICTS[0],
            VerdictCause::Unexplained => NO_CAUSE_VERDICTS[1],
            VerdictCause::Inconclusive => NO_CAUSE_VERDICTS[2],
        }
    }

    /// A cause is named (of the catalog or of the user's).
    pub fn names_a_cause(&self) -> bool {
        matches!(self, VerdictCause::Catalog(_) | VerdictCause::User(_))
    }
}

impl std::fmt::Display for VerdictCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for VerdictCause {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl PartialEq<str> for VerdictCause {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<&str> for VerdictCause {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

impl PartialEq<String> for VerdictCause {
    fn eq(&self, other: &String) -> bool {
        self.as_str() == other
    }
}

impl PartialEq<VerdictCause> for String {
    fn eq(&self, other: &VerdictCause) -> bool {
        self == other.as_str()
    }
}

impl PartialEq<VerdictCause> for &str {
    fn eq(&self, other: &VerdictCause) -> bool {
        *self == other.as_str()
    }
}

impl Verdict {
    /// A cause is named (not one of [`NO_CAUSE_VERDICTS`]).
    pub fn names_a_cause(&self) -> bool {
        self.cause.names_a_cause()
    }
}

/// How much a named cause can be trusted.
///
/// - `Strong`: a posterior probability of at least [`STRONG_PROBABILITY`] in the open world
///   ([`Confidence`]), its gain holding on the held-out blocks and on the other fold, and the
///   evidence specific to it: its acting parameters identified, the misfit it was named for
///   gone with it, the data's own evidence (not only calibrated values returning to their
///   datasheet) above the threshold. [`Confidence::not_strong`] says which of these failed.
/// - `Moderate`: named (posterior at least [`NAME_PROBABILITY`]), with less than that (a
///   reviewer should check the evidence quoted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Grade {
    Strong,
    Moderate,
}

impl Grade {
    pub fn as_str(self) -> &'static str {
        match self {
            Grade::Strong => "strong",
            Grade::Moderate => "moderate",
        }
    }
}

/// The posterior probability a named cause needs to be graded `strong`: 0.99, i.e. odds of at
/// least 99:1 against the baseline and all rivals together (a BIC margin of about 9.2 against a
/// single alternative, Kass & Raftery's "strong" to "very strong" boundary of 2 ln B = 10 for
/// the sum of several).
pub const STRONG_PROBABILITY: f64 = 0.99;

/// The posterior probability below which no cause is named: one half, the point where the
/// cause is less likely than the alternatives together (its baseline, its rivals, an effect
/// outside the catalog). Below it a name would more often be wrong than right.
pub const NAME_PROBABILITY: f64 = 0.5;

/// The named cause's confidence in an open world: its posterior probability against the
/// alternatives, each alternative's odds against it, what they are computed from, and why it
/// is not `strong` (empty when it is). One computation names the cause (a probability of at
/// least [`NAME_PROBABILITY`]) and states its probability
/// ([`super::ranking::confidence`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Confidence {
    pub probability: f64,
    /// Odds of its re-fitted baseline (no extension) against it, `e^{−2lnB/2}` with the
    /// record's evidence `2 ln B` ([`Gains::record_evidence`]).
    pub odds_baseline: f64,
    /// Odds of the other significant candidates' extended models together, from their BIC on
    /// the fitted samples and their prediction of the held-out samples.
    pub odds_rivals: f64,
    /// Odds of an effect outside the catalog that this extension only mimics.
    pub odds_outside: f64,
    /// The data's own evidence for the extension, `2 ln B` with the priors' rows left out: what
    /// the extension gains on the record, not by returning calibrated values to their
    /// datasheet.
    pub data_evidence: f64,
    /// The fitted χ² the extension leaves beyond what a right catalog block may leave (the
    /// noise floor and its model-form tolerance), in independent samples (VIF-deflated).
    pub misfit_left: f64,
    /// Why the grade is not `strong` (empty when it is).
    pub not_strong: Vec<String>,
}

/// Noise and split.
#[derive(Debug, Clone, Serialize)]
pub struct NoiseModel {
    /// The playback and its compared channels (`"phasor: P, Q"`: [`super::Playback::describe`]).
    pub playback: String,
    /// The noise floor of each compared channel, `(signal, σ)` [pu]; the χ² weights are `1/σ²`.
    pub sigmas: Vec<(String, f64)>,
    /// σ_P and σ_Q of the phasor playback (`null` in a mode that does not compare them).
    pub sigma_p: f64,
    pub sigma_q: f64,
    pub split: String,
    pub n_fit: usize,
    pub n_held: usize,
    /// Per event (fitted, then held out) the floors and the residual of the unit as given
    /// ([`crate::noise::assess`]): the numbers of the headline.
    pub events: Vec<crate::noise::NoiseRow>,
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
    /// The residual of the unit as given against the noise, in one sentence: the same
    /// computation as a fit's report on its calibrated unit ([`crate::noise::assess`]).
    pub headline: crate::noise::Headline,
    /// Plausibility warnings on the inputs (set by [`crate::job::run_diagnose`]).
    pub warnings: Vec<itaipu_dynamics::plausibility::Finding>,
    /// Calibrated parameters freed again in every re-fit ([`super::DiagnoseOptions::refit`]).
    pub refit: Vec<FreeBound>,
    /// Where the time went ([`ProfileRow`]), for the speed work.
    pub profile: Vec<ProfileRow>,
    pub seed: u64,
    pub threads: usize,
    pub wall_s: f64,
    /// What the reference re-fitted beyond the nuisance offsets, and why (absent: the offsets
    /// alone): the calibrated set on every compared channel with a global search when the record
    /// holds the field ([`super::ReferenceRefit`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<super::ReferenceRefit>,
}

/// One row of a diagnosis' profile: the re-fits of one kind (`reference`, `baselines`,
/// `extensions`, `baseline again`, `segments test`, `surrogate (noise-only) re-fits`; or
/// `diagnosis` for the steps outside the re-fits) in one phase (`grid scan`, `swarm`, `local`,
/// `χ² (accurate)`, `whole re-fit` which counts the re-fits and holds their whole wall time).
/// The times are summed over the re-fits of a row; the candidates' re-fits run side by side, so
/// on several threads the sums can exceed the diagnosis's wall time (on one they cannot).
#[derive(Debug, Clone, Serialize)]
pub struct ProfileRow {
    pub kind: String,
    pub phase: String,
    pub wall_s: f64,
    pub simulations: usize,
    pub refits: usize,
}

/// One line of where a diagnosis' time went: each kind of re-fit's whole time and count, then
/// the steps outside the re-fits (`"reference 1.2 s (1 re-fit), baselines 4.0 s (5), …"`).
pub fn profile_summary(rows: &[ProfileRow]) -> String {
    rows.iter()
        .filter(|r| r.phase == "whole re-fit" || r.kind == "diagnosis")
        .map(|r| {
            if r.kind == "diagnosis" {
                format!("{} {:.1} s", r.phase, r.wall_s)
            } else {
                format!(
                    "{} {:.1} s ({} re-fit{})",
                    r.kind,
                    r.wall_s,
                    r.refits,
                    if r.refits == 1 { "" } else { "s" }
                )
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Result of [`super::diagnose`].
pub struct DiagnoseResult {
    pub report: Diagnosis,
    /// The extended, re-fitted unit of the named cause.
    pub extended_unit: Option<Unit>,
    /// Per event: traces of the unit as given.
    pub before: Vec<(String, Traces)>,
    /// Per event: traces of the extended unit (empty when none is named).
    pub after: Vec<(String, Traces)>,
}

/// A number as the statements print it: four decimals, or four significant digits in
/// scientific notation when it is very small or large.
pub(super) fn fmt_num(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The verdict's cause is written as the strings the reports, the Python module and the
    /// fleet read: the cause's id, or `none`, `unexplained`, `inconclusive`; only a catalog or a
    /// user cause names one.
    #[test]
    fn a_verdicts_cause_is_written_as_its_id() {
        let cases = [
            (VerdictCause::Catalog("saturation"), "saturation", true),
            (
                VerdictCause::User("reactive_droop".into()),
                "reactive_droop",
                true,
            ),
            (VerdictCause::None, "none", false),
            (VerdictCause::Unexplained, "unexplained", false),
            (VerdictCause::Inconclusive, "inconclusive", false),
        ];
        for (cause, id, named) in cases {
            assert_eq!(serde_json::to_value(&cause).unwrap(), id);
            assert_eq!(cause.to_string(), id);
            assert_eq!(cause, id);
            assert_eq!(cause.names_a_cause(), named, "{id}");
            assert_eq!(NO_CAUSE_VERDICTS.contains(&id), !named, "{id}");
        }
    }
}
