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
//!    extension, so a gain is the extension's alone. The events play their voltage back as
//!    they say (smoothed at 4 Hz by default); a cause whose mode lies above that cut-off
//!    ([`catalog::Cause::band_top_hz`], the torsional mode) has its baseline, extension and
//!    surrogates played back as recorded (`candidates::RecordedInput`), and is compared with
//!    the other causes without the echo of the voltage's noise that input adds
//!    ([`Gains::input_echo`]).
//!    The candidates are scored side by side (`candidates::Candidates::score_all`, their re-fits'
//!    swarms on the same thread pool): the batch's main baselines are re-fitted first, once
//!    each, and shared; a surrogate's or the segments' baseline a candidate re-fits itself; and
//!    a re-fit depends only on its bounds, split and the diagnosis's seed, so the reports are
//!    those of one cause after another, on any number of threads.
//! 5. **Gain.** `Δχ²` on the fitted samples, the relative drop of the fitted and of the held-out
//!    χ², each net of the gain the same re-fits achieve on a surrogate of the events (the
//!    reference's own simulation with the noise drawn again: pure noise fitting; the residuals'
//!    part of that gain only, not the priors', see `held_out`), and the
//!    Bayesian information criterion difference `ΔBIC = Δχ²/VIF − k ln(N/VIF)` (k = the
//!    extension's parameters, N = fitted residuals, VIF = `(1 + ρ₁)/(1 − ρ₁)` from the baseline
//!    residual's lag-1 autocorrelation, so that a coloured residual counts as fewer independent
//!    samples): an extension that only buys flexibility gains about `k` in χ² and loses.
//! 6. **Verdict.** A candidate is significant when its fitted χ² is down by at least
//!    `min_fit_drop` (default 0: not up), its held-out χ² by at least `min_held_drop`, and the
//!    whole record's evidence `ΔBIC + Δχ²_held/VIF` (the fitted blocks' Bayes factor times the
//!    held-out blocks' predictive likelihood ratio, `2 ln B`) is above `bic_threshold`. Among
//!    the significant ones, the extended model with the lowest `χ²_ext + k ln N` (k = every
//!    parameter it re-fitted) is the best; an extension pressed against the upper end of its
//!    range is not significant (the residual asks for more than the cause can be), nor is one
//!    whose fitted values are no unit of its cause or below what the data resolve
//!    ([`catalog::Cause::vetoed`]: a saturation curve falling with flux, a shaft mode at the
//!    torsional band's lower edge or damped above ζ = 0.1, an OEL without I²t capacity, a skew
//!    below half a sample), nor one
//!    that leaves most of a misfit above the noise floor in place (it removed a part of another
//!    effect's). The best is
//!    named only when every other significant candidate's extended model is at least
//!    `bic_threshold` above it (VIF-deflated); otherwise the verdict is `inconclusive` with the
//!    competitors. A named cause carries its posterior probability and a grade ([`Grade`]).
//!    With no significant candidate the verdict is `none` (residual RMS within `noise_factor`
//!    of the noise floor) or `unexplained` (with the window and signal where the residual
//!    lives); a candidate that passed the statistical test and was refused by the physical
//!    checks above ([`CandidateReport::passed_test`]) makes it `unexplained` at the floor too
//!    (an effect is there that the catalog does not name). In a full diagnosis where a
//!    candidate passed its test (significant or refused), the bundled effects outside the
//!    catalog ([`look_alike`]: a reactive droop, a transducer lag, a speed filter, a PSS
//!    lead-lag, a UEL) are scored too and ranked with the others, never named: when one is the
//!    best the verdict is `unexplained` (what the residual looks like, and the cause file that
//!    names it), when one is within `bic_threshold` of the best it is `inconclusive`.
//!
//! # Recorded field channels
//!
//! When every event also records the field (E_fd, X_ad I_fd: [`playback::FIELD_CHANNELS`]), the
//! phasor playback compares them with P and Q, every channel weighted by `1/σ_c²` with σ_c its
//! own pre-event noise floor, through the same path as a playback mode's channels. A calibration
//! on P and Q alone can absorb a ceiling or a saturation by bending X_d and the exciter's gain,
//! which leaves the simulated field many noise widths off the recorded one: the recorded field
//! is the evidence that bending cannot fake.
//!
//! # Records without an angle
//!
//! A staged test (|V|, P, Q, E_fd from the excitation system's recorder, no voltage angle) is
//! diagnosed in the playback mode the user names ([`DiagnoseOptions::mode`], [`Playback`]):
//! every step above runs on that mode's compared channels instead of P and Q (each weighted by
//! `1/σ_c²`, σ_c its pre-step noise floor), the surrogate events redraw the noise of every
//! recorded channel, the evidence reads each compared residual against the imposed inputs
//! (|V| where it is imposed, the declared set point), a set-point step counts as a dip of its
//! size for the limits' regime, and a cause whose extension acts on a part of the unit the mode
//! does not simulate, or on nothing it compares, is not applicable with the reason
//! ([`catalog::Context::not_seen`]). Without a mode such a record is refused
//! ([`DiagnoseError::Event`]).
//!
//! The residuals of a calibrated model are rarely white, so χ² overstates the evidence when the
//! model error dominates the noise; the held-out check and the relative-drop threshold guard
//! against naming a cause that only absorbs some structured misfit.
//!
//! # Layout
//!
//! Each file holds one step or one idea, and names only files above it in this list
//! (`python3 tools/rust_structure.py floors crates/calib/src diagnose/` prints the floors):
//!
//! - `error`, `report`, `context`: the errors, what is reported (the verdict's
//!   [`VerdictCause`] among it), what the operating point and the playback tell the causes;
//! - `not_applicable`, `cause`, `cause_kit`, `causes/`, `catalog`, `cause_file`, `user_cause`,
//!   `look_alike`: what a cause is ([`catalog::Cause`], its [`catalog::Extension`], the
//!   [`NotApplicable`] reasons it may not be scored) and what it builds its extension with;
//!   one file per built-in cause and their registry; the causes read from files and the
//!   bundled ones outside the catalog;
//! - `playback`, `split`, `windows`, `noise`, `profile`, `calibrated`: what is played back and
//!   compared, the fitted and held-out samples, the per-event evidence, the noise floors and
//!   the surrogate records, where the time goes, the calibrated set every re-fit frees again;
//! - `options`: the options and their defaults;
//! - `refit`, `baseline_cache`, `reference`: the re-fit every reference, baseline and extension
//!   is, the baselines kept by their `BaselineKey`, the nuisance re-fit with its evidence and
//!   the causes' context;
//! - `gain`, `extension_fit`, `held_out`: the statistics a gain is judged by, the extension's
//!   re-fit from its starts, the tests on samples a re-fit did not fit;
//! - `candidates`, `steps`: the batch of candidates and the typed steps that score one
//!   (baseline, extension, held-out tests, comparison, judgement);
//! - `ranking`, `statements`, `verdict`: how candidates compare, the grade, the verdict and
//!   its statement;
//! - `run`: [`diagnose`], the steps in order; `trial` the synthetic self-test.

mod absorbed;
mod baseline_cache;
mod calibrated;
mod candidates;
pub mod catalog;
mod cause;
mod cause_file;
mod cause_kit;
pub mod causes;
mod context;
mod error;
mod extension_fit;
mod fold_check;
mod gain;
mod held_out;
pub mod look_alike;
mod noise;
mod not_applicable;
mod options;
pub mod playback;
mod profile;
mod ranking;
mod reference;
mod refit;
mod report;
mod run;
mod split;
mod statements;
mod steps;
pub mod trial;
pub mod user_cause;
mod verdict;
mod windows;

pub use calibrated::{calibrated_set, merge_calibrated_set, refit_bounds, RefitRequest};
pub use error::DiagnoseError;
pub use noise::REFIT_RMS_NOTE;
pub use not_applicable::NotApplicable;
pub use options::{
    DiagnoseOptions, Fold, DEFAULT_LOCAL_ITERATIONS, DEFAULT_PARTICLES, DEFAULT_PSO_ITERATIONS,
    DEFAULT_SEED,
};
pub use playback::Playback;
pub use reference::{context, ReferenceChannel, ReferenceRefit};
pub use report::{
    profile_summary, CandidateParam, CandidateReport, Confidence, DiagnoseResult, Diagnosis,
    Distortion, EventEvidence, Gains, Grade, NoiseModel, ProfileRow, Verdict, VerdictCause,
    NAME_PROBABILITY, NO_CAUSE_VERDICTS, SHAFT_BAND_HZ, STRONG_PROBABILITY,
};
pub use run::diagnose;
pub use windows::{event_evidence, windows};
