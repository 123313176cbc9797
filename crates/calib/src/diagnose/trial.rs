//! Self-test of the diagnosis on synthetic data: hide a catalog cause in a true unit, make a
//! noisy PMU event from it, calibrate a nominal unit that starts 20-50 % off the truth, diagnose
//! the calibrated unit, and score whether the hidden cause was named first with its key
//! parameter recovered.
//!
//! Used by the integration tests (`tests/diagnose.rs`) and by the hit-rate sweep
//! (`examples/diagnose_sweep.rs`), so both run exactly the same protocol.

use std::collections::BTreeMap;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, VoltageProfile};
use itaipu_dynamics::unit::Unit;

use super::calibrated::{calibrated_set, merge_calibrated_set};
use super::catalog;
use super::cause::HideError;
pub use super::cause::Tolerance;
use super::error::DiagnoseError;
use super::options::DiagnoseOptions;
use super::reference::context;
use super::report::Diagnosis;
use super::run::diagnose;
use crate::fit::{fit, quick_options, FitError, Silent};
use crate::spec::{CalibSpec, SpecError};

/// The calibration run before diagnosing: one stage on the full unit (`tg` removes no block),
/// over the machine and AVR parameters that the nominal unit gets wrong.
pub const NOMINAL_SPEC: &str = r#"
[calibration]
[[calibration.stage]]
name = "tg"
objective = "pq"
free = [
  { param = "machine.h", min = 2.0, max = 9.0 },
  { param = "machine.x_d_prime", min = 0.15, max = 0.6 },
  { param = "exciter.k", min = 30.0, max = 300.0 },
  { param = "exciter.te", min = 0.02, max = 0.2 },
]
"#;

/// How far the nominal unit starts from the truth (factor per parameter).
///
/// T'_d0 is held at its (true) datasheet value, as in a MOD-026 study where it comes from the
/// open-circuit test: from P and Q alone it is not separable from an exciter ceiling. With E_fd
/// on the ceiling the field flux rises at E_MAX/T'_d0, and on the `exciter_limit` trial the fit
/// is as good along E_MAX/T'_d0 = const (RMS of Q 0.00245 pu at the truth, 0.00243 pu with
/// E_MAX 6 % higher and T'_d0 to match), so a calibration that frees both cannot recover the
/// ceiling.
pub const NOMINAL_OFFSETS: &[(&str, f64)] = &[
    ("machine.h", 1.3),
    ("machine.x_d_prime", 0.75),
    ("exciter.k", 0.7),
    ("exciter.te", 1.5),
];

/// One synthetic trial.
#[derive(Debug, Clone)]
pub struct Trial {
    /// The hidden cause (`none` for a clean event).
    pub cause: String,
    /// Values of the extension's parameters in the truth.
    pub values: BTreeMap<String, f64>,
    /// Parameter whose recovery is scored, with its tolerance: relative (`Rel`) or absolute.
    pub key: Option<(String, Tolerance)>,
    pub kind: EventKind,
    pub duration_s: f64,
    pub seed: u64,
    pub noise: PmuNoise,
}

/// Outcome of a trial.
#[derive(Clone)]
pub struct TrialOutcome {
    pub report: Diagnosis,
    /// The verdict's cause.
    pub named: String,
    /// The key parameter: truth and recovered value (if the verdict named the hidden cause).
    pub key: Option<(String, f64, Option<f64>)>,
    /// Named the hidden cause (or `none` for a clean event) and recovered the key parameter.
    pub hit: bool,
    pub event: Event,
    pub calibrated: Unit,
}

/// The generic synthetic hydro unit (GENSAE + SEXS + STAB3 + HYGOV).
pub fn base_unit() -> Unit {
    itaipu_dynamics::unit_file::parse_unit(
        include_str!("../../../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml"),
        std::path::Path::new("data/synthetic/unit_gensae_sexs_stab3_hygov.toml"),
    )
    .expect("the bundled synthetic unit parses")
}

/// PMU noise of the trials: the typical M-class PMU of [`PmuNoise::typical`] (0.002 pu white
/// noise on P and Q with 0.0014 pu quantisation; 5e-4 pu on |V| and 5e-4 rad on the angle). The
/// voltage is the playback's input: its noise reaches the simulated P and Q through the model
/// (errors in variables), which the default playback's 4 Hz smoothing of the record's voltage
/// removes.
pub fn trial_noise(seed: u64) -> PmuNoise {
    PmuNoise::typical(seed)
}

/// A trial with the defaults of the tests: 20 s at 60 samples/s, [`trial_noise`].
pub fn trial(
    cause: &str,
    values: &[(&str, f64)],
    key: Option<(&str, Tolerance)>,
    kind: EventKind,
    seed: u64,
) -> Trial {
    Trial {
        cause: cause.into(),
        values: values.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        key: key.map(|(k, t)| (k.to_string(), t)),
        kind,
        duration_s: 20.0,
        seed,
        noise: trial_noise(seed),
    }
}

/// Why a trial could not run.
#[derive(Debug, thiserror::Error)]
pub enum TrialError {
    /// The synthetic event (the probe or the trial's) could not be made.
    #[error("{0}")]
    Synthesis(String),
    /// The cause could not be hidden in the truth.
    #[error(transparent)]
    Hide(#[from] HideError),
    /// The nominal unit or its calibration spec.
    #[error("{0}")]
    Setup(String),
    #[error(transparent)]
    Spec(#[from] SpecError),
    #[error(transparent)]
    Fit(#[from] FitError),
    /// The context of the truth, or the diagnosis.
    #[error(transparent)]
    Diagnose(#[from] DiagnoseError),
}

impl TrialError {
    /// Short stable identifier of the variant (`"synthesis"`, `"hide"`, `"setup"`, `"spec"`,
    /// `"fit"`, `"diagnose"`).
    pub fn kind(&self) -> &'static str {
        match self {
            TrialError::Synthesis(_) => "synthesis",
            TrialError::Hide(_) => "hide",
            TrialError::Setup(_) => "setup",
            TrialError::Spec(_) => "spec",
            TrialError::Fit(_) => "fit",
            TrialError::Diagnose(_) => "diagnose",
        }
    }
}

/// The noiseless playback of `profile` through `base` (737 MVA base, the trials' own) and the
/// context a cause is hidden in ([`catalog::hide`], [`super::user_cause::UserCause::hide`]):
/// the event kind, the rate, the operating point.
pub fn probe(
    base: &Unit,
    profile: &VoltageProfile,
) -> Result<(Event, catalog::Context), TrialError> {
    let probe = synthesize(
        "probe",
        base,
        profile,
        737.0,
        &PmuNoise::none(),
        &SimOptions::default(),
    )
    .map_err(|e| TrialError::Synthesis(e.to_string()))?;
    let ctx = context(base, &probe)?;
    Ok((probe, ctx))
}

/// The truth unit of a trial and its event.
pub fn truth_and_event(t: &Trial) -> Result<(Unit, Event), TrialError> {
    let base = base_unit();
    let profile = VoltageProfile::preset(t.kind, t.duration_s, 60.0, t.seed);
    let sim = SimOptions::default();
    let truth = if t.cause == "none" {
        base
    } else {
        catalog::hide(&t.cause, &base, &probe(&base, &profile)?.1, &t.values)?.0
    };
    let event = synthesize(
        &format!("trial-{}-{}", t.cause, t.seed),
        &truth,
        &profile,
        737.0,
        &t.noise,
        &sim,
    )
    .map_err(|e| TrialError::Synthesis(e.to_string()))?;
    Ok((truth, event))
}

/// Runs a trial: truth and event, calibration of the nominal unit, diagnosis, score.
///
/// The diagnosis re-frees the calibration's free parameters in every re-fit (added to
/// `opts.refit`: [`calibrated_set`] merged by [`merge_calibrated_set`]), as
/// the command line, Python and the practice runner do: a re-fit whose baseline cannot move
/// what the calibration bent lets any extension that mimics the bend gain, and the trials
/// measure the protocol a user gets.
pub fn run(t: &Trial, opts: &DiagnoseOptions) -> Result<TrialOutcome, TrialError> {
    let (truth, event) = truth_and_event(t)?;
    let mut nominal = base_unit();
    for (p, f) in NOMINAL_OFFSETS {
        let r = nominal
            .param(p)
            .map_err(|e| TrialError::Setup(e.to_string()))?;
        let v = nominal.get(r);
        nominal.set(r, v * f);
    }
    let spec = CalibSpec::parse(NOMINAL_SPEC, std::path::Path::new("nominal-spec.toml"))?;
    let fit_opts = quick_options(&["tg"], t.seed);
    let fitted = fit(
        &nominal,
        &spec,
        std::slice::from_ref(&event),
        &[],
        &fit_opts,
        &Silent,
    )?;
    let calibrated = fitted.unit;
    let mut opts = opts.clone();
    merge_calibrated_set(
        &mut opts.refit,
        &calibrated_set(&spec, &fit_opts.stages, &nominal, &calibrated),
        &calibrated,
    );
    let res = diagnose(
        &calibrated,
        std::slice::from_ref(&event),
        &[],
        &opts,
        &Silent,
    )?;
    let named = res.report.verdict.cause.to_string();
    let key = t.key.as_ref().map(|(p, _)| {
        let tv = truth.param(p).map(|r| truth.get(r)).unwrap_or(f64::NAN);
        let got = res
            .report
            .verdict
            .key_parameters
            .iter()
            .find(|(q, _, _)| q == p)
            .map(|(_, v, _)| *v);
        (p.clone(), tv, got)
    });
    let named_right = named == t.cause;
    let key_ok = match (&t.key, &key) {
        (Some((_, tol)), Some((_, tv, Some(got)))) => match tol {
            Tolerance::Rel(r) => (got - tv).abs() <= r * tv.abs(),
            Tolerance::Abs(a) => (got - tv).abs() <= *a,
        },
        (Some(_), _) => false,
        (None, _) => true,
    };
    Ok(TrialOutcome {
        report: res.report,
        named,
        key,
        hit: named_right && key_ok,
        event,
        calibrated,
    })
}

/// The canonical scenario for hiding `cause`, varied by `seed` (parameter values drawn around a
/// centre, the noise and the grid's fluctuations seeded). `kind` overrides the event type.
pub fn scenario(cause: &str, seed: u64, kind: Option<EventKind>) -> Trial {
    // A deterministic spread in [-1, 1] from the seed.
    let u = |salt: u64| {
        let mut r =
            itaipu_dynamics::synthetic::Normal::new(seed.wrapping_mul(7919).wrapping_add(salt));
        2.0 * r.uniform() - 1.0
    };
    let mut t = match catalog::cause(cause).and_then(|c| c.scenario(&u)) {
        Some(s) => trial(cause, &s.values, s.key, s.kind, seed),
        None => trial("none", &[], None, EventKind::FaultDip, seed),
    };
    if let Some(k) = kind {
        t.kind = k;
    }
    t
}

/// A fault dip of `duration_s` at 60 samples/s into `unit`, with PMU noise of `seed`: the
/// record of [`dip_problem`].
pub fn dip_event(unit: &Unit, duration_s: f64, seed: u64) -> Event {
    let profile = VoltageProfile {
        duration_s,
        ..VoltageProfile::default()
    };
    synthesize(
        "dip",
        unit,
        &profile,
        60.0,
        &PmuNoise::typical(seed),
        &Default::default(),
    )
    .expect("a dip into a unit that initialises")
}

/// [`dip_event`] with the field recorded too: `unit`'s E_fd and X_ad I_fd in the phasor
/// playback, with white noise of 0.01 and 0.005 pu (seed `field_seed`, E_fd's draws first).
pub fn dip_event_with_field(unit: &Unit, duration_s: f64, seed: u64, field_seed: u64) -> Event {
    use itaipu_dynamics::mode::{simulate_mode, PlaybackMode};
    use itaipu_dynamics::simulate::PreparedEvent;
    let dip = dip_event(unit, duration_s, seed);
    let out = simulate_mode(
        unit,
        &PreparedEvent::new(&dip),
        PlaybackMode::Phasor,
        &SimOptions::default(),
    )
    .expect("the dip's unit plays back");
    let mut rng = itaipu_dynamics::rng::Normal::new(field_seed);
    let mut noisy = |y: &[f64], s: f64| y.iter().map(|v| v + s * rng.sample()).collect();
    let mut rec = dip.record.clone();
    rec.efd_pu = Some(noisy(&out.efd, 0.01));
    rec.ifd_pu = Some(noisy(&out.ifd, 0.005));
    Event::from_record(
        "dip with field",
        rec,
        dip.system_mva,
        dip.nominal_hz,
        Some(dip.init),
        Some(dip.fit),
    )
    .expect("the dip's record with its field")
}

/// The least-squares problem of a fault dip (`duration_s` at 60 samples/s, PMU noise of `seed`)
/// played into `unit`, with `free` parameters (path, lower and upper bound) starting at
/// `start_scale` times their values in `unit`: the Jacobian tests' and benchmarks' problem.
///
/// The record is played back as recorded, not smoothed at the default cut-off: its voltage
/// noise above 4 Hz is what keeps the columns of the fast parameters (a 5-50 ms voltage
/// transducer's lag) well above the adaptive integrator's step noise, which the Jacobian
/// checks need to compare columns at a few per cent (smoothed, the transducer's column shrinks
/// toward that noise).
pub fn dip_problem(
    unit: Unit,
    free: &[(&str, f64, f64)],
    duration_s: f64,
    seed: u64,
    start_scale: f64,
) -> crate::problem::Problem {
    let mut ev = dip_event(&unit, duration_s, seed);
    ev.input_lowpass_hz = None;
    event_problem(unit, &ev, free, start_scale)
}

/// The least-squares problem of `event` played into `unit`, with `free` parameters (path, lower
/// and upper bound) starting at `start_scale` times their values in `unit`, P and Q weighted
/// alike.
pub fn event_problem(
    unit: Unit,
    ev: &Event,
    free: &[(&str, f64, f64)],
    start_scale: f64,
) -> crate::problem::Problem {
    use crate::problem::{EventData, FreeParam, Problem};
    let free: Vec<FreeParam> = free
        .iter()
        .map(|&(p, lo, hi)| {
            let r = unit.param(p).expect("a parameter of the unit");
            FreeParam::new(p.into(), r, lo, hi, start_scale * unit.get(r), "")
        })
        .collect();
    let data = vec![EventData::new(ev, None, None).expect("a usable event")];
    Problem::new(unit, free, data, (1.0, 1.0))
}
