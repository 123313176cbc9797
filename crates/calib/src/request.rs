//! Validated requests: the options both front ends (the command line and the Python module)
//! take for `simulate`, `synth`, `fit` and `diagnose`, parsed and checked once, here. A front
//! end only reads its arguments into these types, calls [`SimulateRequest::options`],
//! [`SynthRequest::validate`], [`FitRequest::apply`] or [`Search::validate`], and renders a
//! [`RequestError`] with its own spelling of the option names ([`Style`]: `--pq-sigma` on the
//! command line, `pq_sigma` in Python).

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::integrate::{Dopri5Options, Method};
use itaipu_dynamics::simulate::SimOptions;
use itaipu_dynamics::synthetic::{synthesize, EventKind, PmuNoise, SynthError, VoltageProfile};
use itaipu_dynamics::unit::Unit;

use crate::diagnose::{self, catalog, DiagnoseError, DiagnoseOptions, RefitRequest};
use crate::fit::FitOptions;
use crate::spec::{Strategy, STAGES};

// -------------------------------------------------------------------------------------------
// Errors
// -------------------------------------------------------------------------------------------

/// How a front end spells option names in messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// `--pq-sigma`.
    Cli,
    /// `pq_sigma` (also the [`fmt::Display`] form).
    Python,
}

impl Style {
    /// The option `name` (snake case) as this front end spells it.
    pub fn option(self, name: &str) -> String {
        match self {
            Style::Cli => format!("--{}", name.replace('_', "-")),
            Style::Python => name.to_string(),
        }
    }
}

/// One piece of a [`RequestError`] message.
#[derive(Debug, Clone, PartialEq)]
enum Piece {
    Text(String),
    Option(&'static str),
}

/// A rejected option: a usage error (exit code 2 on the command line, ValueError in Python).
/// The message names options through [`Style`].
#[derive(Debug, Clone, PartialEq)]
pub struct RequestError {
    /// The option at fault (snake case).
    pub option: &'static str,
    pieces: Vec<Piece>,
}

impl RequestError {
    /// `<option> <text>`.
    pub(crate) fn new(option: &'static str, text: impl Into<String>) -> Self {
        Self {
            option,
            pieces: vec![Piece::Option(option), Piece::Text(text.into())],
        }
    }

    /// Appends text, or another option's name.
    fn then(mut self, text: impl Into<String>) -> Self {
        self.pieces.push(Piece::Text(text.into()));
        self
    }
    fn then_option(mut self, option: &'static str) -> Self {
        self.pieces.push(Piece::Option(option));
        self
    }

    /// The message with option names spelled in `style`.
    pub fn message(&self, style: Style) -> String {
        self.pieces
            .iter()
            .map(|p| match p {
                Piece::Text(t) => t.clone(),
                Piece::Option(o) => style.option(o),
            })
            .collect()
    }
}

impl fmt::Display for RequestError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message(Style::Python))
    }
}

impl std::error::Error for RequestError {}

/// `value` must be `>= 0` and finite.
fn non_negative(option: &'static str, value: f64) -> Result<(), RequestError> {
    if !(value >= 0.0 && value.is_finite()) {
        return Err(RequestError::new(
            option,
            format!(" must be >= 0 (got {value})"),
        ));
    }
    Ok(())
}

// -------------------------------------------------------------------------------------------
// Names: stages, strategies, integrators
// -------------------------------------------------------------------------------------------

/// A calibration stage as named on the command line and in Python, or `all`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    Gen,
    Avr,
    Pss,
    Tg,
    /// Every stage the spec lists.
    All,
}

impl Stage {
    /// The names, in the fixed order stages run in, then `all`.
    pub const NAMES: [&'static str; 5] = ["gen", "avr", "pss", "tg", "all"];

    /// Every stage, in the order of [`Stage::NAMES`].
    const ALL: [Stage; 5] = [Stage::Gen, Stage::Avr, Stage::Pss, Stage::Tg, Stage::All];

    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// Stage names (each may hold several, comma-separated) as stages: at least one.
    pub fn parse_list<S: AsRef<str>>(given: &[S]) -> Result<Vec<Stage>, RequestError> {
        let names: Vec<String> = given
            .iter()
            .flat_map(|s| s.as_ref().split(','))
            .map(|s| s.trim().to_string())
            .collect();
        if names.is_empty() {
            return Err(RequestError::new(
                "stages",
                " must name at least one stage (gen, avr, pss, tg) or be 'all'",
            ));
        }
        names
            .iter()
            .map(|n| {
                n.parse::<Stage>()
                    .map_err(|e| RequestError::new("stages", format!(": {e}")))
            })
            .collect()
    }

    /// The stages to run: None for `all` (every stage the spec lists), else the named ones in
    /// the fixed order gen, avr, pss, tg.
    pub fn selection(stages: &[Stage]) -> Option<Vec<String>> {
        if stages.contains(&Stage::All) {
            return None;
        }
        Some(
            STAGES
                .iter()
                .filter(|s| stages.iter().any(|g| g.name() == **s))
                .map(|s| s.to_string())
                .collect(),
        )
    }
}

/// An unknown stage name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown stage '{0}' (gen, avr, pss, tg or all)")]
pub struct UnknownStage(pub String);

impl FromStr for Stage {
    type Err = UnknownStage;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        Stage::ALL
            .into_iter()
            .find(|st| st.name() == name)
            .ok_or(UnknownStage(name))
    }
}

impl FromStr for Strategy {
    type Err = RequestError;
    /// `sequential`, `incremental` or `simultaneous-first` (any case).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.to_ascii_lowercase();
        Strategy::ALL
            .into_iter()
            .find(|st| st.name() == name)
            .ok_or_else(|| {
                let quoted: Vec<String> =
                    Strategy::NAMES.iter().map(|n| format!("'{n}'")).collect();
                let (last, rest) = quoted.split_last().expect("strategies");
                RequestError::new(
                    "strategy",
                    format!(" must be {} or {last} (got '{s}')", rest.join(", ")),
                )
            })
    }
}

// -------------------------------------------------------------------------------------------
// simulate
// -------------------------------------------------------------------------------------------

/// The integrator options of `simulate`: the method by name (see [`Method`]'s `FromStr`) and
/// its settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulateRequest {
    pub method: String,
    /// Relative tolerance (dopri5).
    pub rtol: f64,
    /// Absolute tolerance (dopri5).
    pub atol: f64,
    /// Largest step [s] (rk4).
    pub step: f64,
}

impl Default for SimulateRequest {
    /// [`crate::options::SIMULATE`].
    fn default() -> Self {
        let d = crate::options::SIMULATE;
        Self {
            method: d.method.into(),
            rtol: d.rtol,
            atol: d.atol,
            step: d.step,
        }
    }
}

impl SimulateRequest {
    /// The simulation options, checked: rk4 needs `step > 0`, dopri5 `rtol > 0` and
    /// `atol >= 0` (everything else as in [`SimOptions::default`]).
    pub fn options(&self) -> Result<SimOptions, RequestError> {
        let method = match self
            .method
            .parse::<Method>()
            .map_err(|e| RequestError::new("method", format!(" {e}")))?
        {
            Method::Rk4 { .. } => {
                if !(self.step > 0.0 && self.step.is_finite()) {
                    return Err(RequestError::new(
                        "step",
                        format!(" must be > 0 (got {})", self.step),
                    ));
                }
                Method::Rk4 { h: self.step }
            }
            Method::Dopri5(base) => {
                let (rtol, atol) = (self.rtol, self.atol);
                if !(rtol > 0.0 && atol >= 0.0) {
                    return Err(RequestError::new("rtol", " must be > 0 and ")
                        .then_option("atol")
                        .then(" >= 0 (got ")
                        .then_option("rtol")
                        .then(format!("={rtol}, "))
                        .then_option("atol")
                        .then(format!("={atol})")));
                }
                Method::Dopri5(Dopri5Options { rtol, atol, ..base })
            }
            // Not a name `Method::from_str` gives: logs and replays are made by the calibrator.
            m @ (Method::Dopri5Logged(..) | Method::Replay(_)) => m,
        };
        Ok(SimOptions { method })
    }
}

// -------------------------------------------------------------------------------------------
// Search settings (fit and diagnose)
// -------------------------------------------------------------------------------------------

/// The defaults of a search (a swarm, then the local method), declared once: read by the
/// library, the option declaration ([`crate::options`]: the command line's help and the option
/// reference) and the Python module (`itaipu_calib.defaults()`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct SearchDefaults {
    pub seed: u64,
    pub particles: usize,
    pub pso_iterations: usize,
    /// Iterations of the local method (Levenberg-Marquardt steps, or L-BFGS iterations).
    pub local_iterations: u64,
}

/// A diagnosis' re-fits: each candidate's swarm and local method, per re-fit.
pub const DIAGNOSE_SEARCH: SearchDefaults = SearchDefaults {
    seed: crate::diagnose::DEFAULT_SEED,
    particles: crate::diagnose::DEFAULT_PARTICLES,
    pso_iterations: crate::diagnose::DEFAULT_PSO_ITERATIONS,
    local_iterations: crate::diagnose::DEFAULT_LOCAL_ITERATIONS,
};

/// A fit's, per stage, where the calibration spec does not set them (`[calibration] seed`,
/// `[calibration.pso]`, `[calibration.lbfgs]`).
pub const FIT_SEARCH: SearchDefaults = SearchDefaults {
    seed: crate::spec::DEFAULT_SEED,
    particles: crate::spec::DEFAULT_PARTICLES,
    pso_iterations: crate::spec::DEFAULT_PSO_ITERATIONS,
    local_iterations: crate::spec::DEFAULT_LOCAL_ITERATIONS,
};

/// Swarm, local-method and thread settings given by the user; `None` keeps the spec's or the
/// command's default ([`SearchDefaults`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Search {
    pub seed: Option<u64>,
    pub particles: Option<usize>,
    pub pso_iterations: Option<usize>,
    /// Iterations of the local method (Levenberg-Marquardt or L-BFGS). The command line's
    /// `--local-iterations` (old spelling `--lbfgs-iterations`), Python's `local_iterations`.
    pub local_iterations: Option<u64>,
    pub threads: Option<usize>,
}

impl Search {
    /// A swarm needs at least 2 particles; a pool at least 1 thread.
    pub fn validate(&self) -> Result<(), RequestError> {
        if let Some(n) = self.particles {
            if n < 2 {
                return Err(RequestError::new(
                    "particles",
                    format!(" must be at least 2 (got {n})"),
                ));
            }
        }
        if self.threads == Some(0) {
            return Err(RequestError::new("threads", " must be at least 1"));
        }
        Ok(())
    }

    /// [`Search::validate`], then overrides the given settings with those the user gave (the
    /// fit's or the diagnosis's: [`Search::apply_fit`], [`Search::apply_diagnose`]).
    fn apply(
        &self,
        seed: &mut u64,
        particles: &mut usize,
        pso: &mut usize,
        local: &mut u64,
    ) -> Result<(), RequestError> {
        self.validate()?;
        if let Some(s) = self.seed {
            *seed = s;
        }
        if let Some(n) = self.particles {
            *particles = n;
        }
        if let Some(n) = self.pso_iterations {
            *pso = n;
        }
        if let Some(n) = self.local_iterations {
            *local = n;
        }
        Ok(())
    }

    /// [`Search::apply`] to a fit's options. The user's swarm iterations are every pass's: the
    /// stages' and the joint pass's (the spec's `joint_iterations` then no longer applies).
    pub fn apply_fit(&self, opts: &mut FitOptions) -> Result<(), RequestError> {
        self.apply(
            &mut opts.seed,
            &mut opts.particles,
            &mut opts.pso_iterations,
            &mut opts.lbfgs_iterations,
        )?;
        if self.pso_iterations.is_some() {
            opts.joint_pso_iterations = None;
        }
        Ok(())
    }

    /// [`Search::apply`] to diagnosis options.
    pub fn apply_diagnose(&self, opts: &mut DiagnoseOptions) -> Result<(), RequestError> {
        self.apply(
            &mut opts.seed,
            &mut opts.particles,
            &mut opts.pso_iterations,
            &mut opts.lbfgs_iterations,
        )
    }
}

// -------------------------------------------------------------------------------------------
// fit
// -------------------------------------------------------------------------------------------

/// What the user asks of a fit beyond the spec.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FitRequest {
    /// Stages to run (empty or containing [`Stage::All`]: every stage the spec lists).
    pub stages: Vec<Stage>,
    pub strategy: Option<Strategy>,
    pub search: Search,
    /// Skip the final joint refinement.
    pub no_polish: bool,
}

impl FitRequest {
    /// Checks the request and applies it to the spec's options.
    pub fn apply(&self, opts: &mut FitOptions) -> Result<(), RequestError> {
        if let Some(s) = self.strategy {
            opts.strategy = s;
        }
        if !self.stages.is_empty() {
            if let Some(s) = Stage::selection(&self.stages) {
                opts.stages = s;
            }
        }
        if self.no_polish {
            opts.polish = false;
        }
        self.search.apply_fit(opts)
    }
}

// -------------------------------------------------------------------------------------------
// diagnose
// -------------------------------------------------------------------------------------------

/// A `--refit` request as written: `PARAM` or `PARAM=MIN:MAX` (whether the parameter exists is
/// checked against the unit by [`diagnose::refit_bounds`]).
pub fn parse_refit(text: &str) -> Result<RefitRequest, RequestError> {
    let r = text.trim();
    let bad = |why: &str| {
        RequestError {
            option: "refit",
            pieces: vec![],
        }
        .then_option("refit")
        .then(format!(" {r}: {why} (PARAM or PARAM=MIN:MAX)"))
    };
    match r.split_once('=') {
        None if !r.is_empty() => Ok((r.to_string(), None)),
        None => Err(bad("empty")),
        Some((p, range)) => {
            let (lo, hi) = range
                .split_once(':')
                .ok_or_else(|| bad("no ':' between MIN and MAX"))?;
            let num = |v: &str| {
                v.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(&format!("'{}' is not a finite number", v.trim())))
            };
            Ok((p.trim().to_string(), Some((num(lo)?, num(hi)?))))
        }
    }
}

/// What the user asks of a diagnosis: the causes to try (ids of the catalog or of the user
/// causes; empty = all), the user cause files, calibrated parameters to free again in every
/// re-fit, and the search settings. The calibrated set of a fit is added by the job
/// ([`crate::job::prepare_diagnose`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DiagnoseRequest {
    /// The playback mode of a record without an angle (`None`: the phasor playback).
    pub mode: Option<itaipu_dynamics::mode::PlaybackMode>,
    pub causes: Vec<String>,
    pub user_causes: Vec<std::path::PathBuf>,
    pub refit: Vec<RefitRequest>,
    pub search: Search,
    /// Try the look-alikes outside the catalog ([`DiagnoseOptions::look_alikes`]); `None`: the
    /// options' default (yes).
    pub look_alikes: Option<bool>,
}

impl DiagnoseRequest {
    /// The diagnosis options for `unit`: the user causes read, the cause ids checked against
    /// the catalog and the user causes (in the order given, without duplicates), the re-fit
    /// requests resolved in the unit, the search settings over [`DIAGNOSE_SEARCH`].
    pub fn options(&self, unit: &Unit) -> Result<DiagnoseOptions, crate::Error> {
        self.search.validate()?;
        let user_causes = diagnose::user_cause::read_all(&self.user_causes)?;
        let mut causes: Vec<String> = vec![];
        for c in &self.causes {
            let c = c.trim();
            if !diagnose::user_cause::known(c, &user_causes) {
                return Err(RequestError::new(
                    "cause",
                    format!(
                        ": unknown cause '{c}' (known: {})",
                        diagnose::user_cause::ids(&user_causes)
                    ),
                )
                .into());
            }
            if !causes.iter().any(|k| k == c) {
                causes.push(c.to_string());
            }
        }
        let mut opts = DiagnoseOptions {
            causes,
            user_causes,
            mode: self.mode,
            ..Default::default()
        };
        if let Some(l) = self.look_alikes {
            opts.look_alikes = l;
        }
        self.search.apply_diagnose(&mut opts)?;
        opts.refit = diagnose::refit_bounds(unit, &self.refit)
            .map_err(|e| RequestError::new("refit", format!(": {e} (unit '{}')", unit.name)))?;
        Ok(opts)
    }
}

// -------------------------------------------------------------------------------------------
// synth
// -------------------------------------------------------------------------------------------

/// What happens on the grid side of a synthetic event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SynthKind {
    Dip,
    Frequency,
    Step,
    Ambient,
}

impl SynthKind {
    pub fn name(self) -> &'static str {
        match self {
            SynthKind::Dip => "dip",
            SynthKind::Frequency => "frequency",
            SynthKind::Step => "step",
            SynthKind::Ambient => "ambient",
        }
    }
    pub fn event_kind(self) -> EventKind {
        match self {
            SynthKind::Dip => EventKind::FaultDip,
            SynthKind::Frequency => EventKind::FrequencyExcursion,
            SynthKind::Step => EventKind::VoltageStep,
            SynthKind::Ambient => EventKind::Ambient,
        }
    }
}

impl FromStr for SynthKind {
    type Err = RequestError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let k = s.to_ascii_lowercase();
        match k.as_str() {
            "dip" => Ok(SynthKind::Dip),
            "frequency" => Ok(SynthKind::Frequency),
            "step" => Ok(SynthKind::Step),
            "ambient" => Ok(SynthKind::Ambient),
            _ => Err(RequestError::new(
                "kind",
                format!(" '{k}' is not one of dip, frequency, step, ambient"),
            )),
        }
    }
}

/// A cause of the diagnosis catalog to hide in the truth, with values for some of its
/// extension's parameters, in the order given.
#[derive(Debug, Clone, PartialEq)]
pub struct HideSpec {
    /// As written (`--hide` text), or the cause id.
    pub written: String,
    pub cause: String,
    pub values: Vec<(String, f64)>,
}

impl HideSpec {
    /// A cause and its values given separately (Python): the cause must be in the catalog and
    /// the values finite.
    pub fn new(cause: String, values: Vec<(String, f64)>) -> Result<Self, RequestError> {
        if catalog::find(&cause).is_none() {
            return Err(RequestError::new(
                "hide",
                format!(": unknown cause '{cause}' (known: {})", catalog::ids()),
            ));
        }
        if let Some((k, x)) = values.iter().find(|(_, x)| !x.is_finite()) {
            return Err(RequestError::new(
                "hide",
                format!(": '{cause}': {k} must be finite (got {x})"),
            ));
        }
        Ok(Self {
            written: cause.clone(),
            cause,
            values,
        })
    }

    /// `CAUSE[:PARAM=VALUE,PARAM=VALUE...]` (the command line's `--hide`); every error names
    /// the bad piece.
    pub fn parse(spec: &str) -> Result<Self, RequestError> {
        let usage = |msg: String| RequestError::new("hide", format!(" {spec}: {msg}"));
        let (cause, rest) = match spec.split_once(':') {
            Some((c, r)) => (c.trim(), Some(r)),
            None => (spec.trim(), None),
        };
        if cause.is_empty() {
            return Err(usage(format!(
                "no cause before ':' (known: {})",
                catalog::ids()
            )));
        }
        if catalog::find(cause).is_none() {
            return Err(usage(format!(
                "unknown cause '{cause}' (known: {})",
                catalog::ids()
            )));
        }
        let mut values: Vec<(String, f64)> = vec![];
        if let Some(rest) = rest {
            if rest.trim().is_empty() {
                return Err(usage(
                    "nothing after ':' (expected PARAM=VALUE[,PARAM=VALUE...])".into(),
                ));
            }
            for item in rest.split(',') {
                let (k, v) = item
                    .split_once('=')
                    .ok_or_else(|| usage(format!("'{}' is not PARAM=VALUE", item.trim())))?;
                let (k, v) = (k.trim(), v.trim());
                if k.is_empty() {
                    return Err(usage(format!("'{}' has no parameter name", item.trim())));
                }
                let x: f64 = v
                    .parse()
                    .map_err(|_| usage(format!("{k}: '{v}' is not a number")))?;
                if !x.is_finite() {
                    return Err(usage(format!("{k}: '{v}' is not a finite number")));
                }
                if values.iter().any(|(p, _)| p == k) {
                    return Err(usage(format!("{k} is given twice")));
                }
                values.push((k.to_string(), x));
            }
        }
        Ok(Self {
            written: spec.to_string(),
            cause: cause.to_string(),
            values,
        })
    }
}

/// A synthetic event to make (see [`itaipu_dynamics::synthetic`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SynthRequest {
    pub kind: SynthKind,
    /// Record length [s], above 1.5.
    pub duration: f64,
    /// PMU reporting rate [samples/s], 10 to 1000.
    pub rate: f64,
    /// System base of P and Q [MVA] (default: the unit's machine base).
    pub system_mva: Option<f64>,
    pub pq_sigma: f64,
    pub v_sigma: f64,
    pub quantum: f64,
    pub skew_ms: f64,
    pub seed: u64,
    /// Event name (default: `synthetic-<kind>-<seed>`).
    pub name: Option<String>,
    pub hides: Vec<HideSpec>,
}

impl Default for SynthRequest {
    /// [`crate::options::SYNTH`].
    fn default() -> Self {
        let d = crate::options::SYNTH;
        Self {
            kind: d.kind.parse().expect("the declared kind is a kind"),
            duration: d.duration,
            rate: d.rate,
            system_mva: None,
            pq_sigma: d.pq_sigma,
            v_sigma: d.v_sigma,
            quantum: d.quantum,
            skew_ms: d.skew_ms,
            seed: d.seed,
            name: None,
            hides: vec![],
        }
    }
}

/// A hidden cause as applied: its parameters with their values in the extended unit.
#[derive(Debug, Clone, PartialEq)]
pub struct HiddenCause {
    pub written: String,
    pub cause: String,
    pub title: String,
    pub extension: String,
    pub parameters: Vec<(String, f64)>,
}

/// A synthetic event and the (possibly extended) truth that made it.
#[derive(Clone)]
pub struct Synthesized {
    pub event: Event,
    pub truth: Unit,
    pub hidden: Vec<HiddenCause>,
}

/// Why a synthetic event could not be made.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SynthFailure {
    /// The noise-free probe run of the truth as given (before hiding) failed.
    #[error("{0}")]
    Probe(SynthError),
    /// The catalog's context could not be taken from the probe.
    #[error("the true unit does not simulate on the synthetic profile: {0}")]
    Context(String),
    /// A cause could not be hidden.
    #[error("{error}")]
    Hide {
        written: String,
        error: catalog::HideError,
    },
    /// The final run failed.
    #[error("{0}")]
    Synth(SynthError),
}

impl SynthRequest {
    /// Checks the ranges: duration above 1.5 s, rate 10-1000 samples/s, noise, quantum and
    /// skew `>= 0`, a given system base `> 0`.
    pub fn validate(&self) -> Result<(), RequestError> {
        if !(self.duration > 1.5 && self.duration.is_finite()) {
            return Err(RequestError::new(
                "duration",
                format!(" must exceed 1.5 s (got {})", self.duration),
            ));
        }
        if !(self.rate >= 10.0 && self.rate <= 1000.0) {
            return Err(RequestError::new(
                "rate",
                format!(" must lie in 10-1000 samples/s (got {})", self.rate),
            ));
        }
        non_negative("pq_sigma", self.pq_sigma)?;
        non_negative("v_sigma", self.v_sigma)?;
        non_negative("quantum", self.quantum)?;
        non_negative("skew_ms", self.skew_ms)?;
        if let Some(m) = self.system_mva {
            if !(m > 0.0 && m.is_finite()) {
                return Err(RequestError::new(
                    "system_mva",
                    format!(" must be > 0 (got {m})"),
                ));
            }
        }
        Ok(())
    }

    /// The event name.
    pub fn event_name(&self) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("synthetic-{}-{}", self.kind.name(), self.seed))
    }

    /// The PMU noise model.
    pub fn noise(&self) -> PmuNoise {
        PmuNoise {
            pq_sigma: self.pq_sigma,
            v_sigma: self.v_sigma,
            angle_sigma: self.v_sigma,
            pq_quantum: self.quantum,
            pq_delay_s: self.skew_ms * 1e-3,
            seed: self.seed,
        }
    }

    /// Makes the event from `truth` (after [`SynthRequest::validate`]): with causes to hide, a
    /// noise-free probe run of the truth as given provides the catalog's context, each cause
    /// is hidden in turn, and the extended unit's description says so (`by`: who hid them).
    pub fn run(&self, truth: &Unit, by: &str) -> Result<Synthesized, SynthFailure> {
        let name = self.event_name();
        let profile =
            VoltageProfile::preset(self.kind.event_kind(), self.duration, self.rate, self.seed);
        let mva = self.system_mva.unwrap_or(truth.machine_mva);
        let (truth, hidden) = if self.hides.is_empty() {
            (truth.clone(), vec![])
        } else {
            let probe = synthesize(
                &name,
                truth,
                &profile,
                mva,
                &PmuNoise::none(),
                &SimOptions::default(),
            )
            .map_err(SynthFailure::Probe)?;
            self.hide_all(truth, &probe, by)?
        };
        let event = synthesize(
            &name,
            &truth,
            &profile,
            mva,
            &self.noise(),
            &SimOptions::default(),
        )
        .map_err(SynthFailure::Synth)?;
        Ok(Synthesized {
            event,
            truth,
            hidden,
        })
    }

    /// Hides each cause in turn ([`catalog::hide`]); only the extension's parameters may be
    /// set.
    fn hide_all(
        &self,
        truth: &Unit,
        probe: &Event,
        by: &str,
    ) -> Result<(Unit, Vec<HiddenCause>), SynthFailure> {
        let ctx = diagnose::context(truth, probe).map_err(|e| match e {
            DiagnoseError::Simulation { msg, .. } => SynthFailure::Context(msg),
            other => SynthFailure::Context(other.to_string()),
        })?;
        let mut unit = truth.clone();
        let mut hidden = vec![];
        for h in &self.hides {
            let map: BTreeMap<String, f64> = h.values.iter().cloned().collect();
            let (extended, ext) =
                catalog::hide(&h.cause, &unit, &ctx, &map).map_err(|error| SynthFailure::Hide {
                    written: h.written.clone(),
                    error,
                })?;
            unit = extended;
            let mut shown: Vec<&str> = ext
                .extension_free
                .iter()
                .map(|f| f.param.as_str())
                .collect();
            shown.extend(ext.ties.iter().map(|(_, to)| to.as_str()));
            shown.extend(h.values.iter().map(|(p, _)| p.as_str()));
            let mut parameters: Vec<(String, f64)> = vec![];
            for p in shown {
                if let Ok(r) = unit.param(p) {
                    if !parameters.iter().any(|(q, _)| q == p) {
                        parameters.push((p.to_string(), unit.get(r)));
                    }
                }
            }
            let title = catalog::find(&h.cause)
                .map(|c| c.title.to_string())
                .unwrap_or_default();
            hidden.push(HiddenCause {
                written: h.written.clone(),
                cause: h.cause.clone(),
                title,
                extension: ext.description.clone(),
                parameters,
            });
        }
        let causes: Vec<&str> = self.hides.iter().map(|h| h.cause.as_str()).collect();
        unit.description = format!(
            "{} (hidden by {by}: {})",
            unit.description,
            causes.join(", ")
        );
        Ok((unit, hidden))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn option_names_follow_the_front_end() {
        let e = SynthRequest {
            pq_sigma: -1.0,
            ..Default::default()
        }
        .validate()
        .unwrap_err();
        assert_eq!(e.message(Style::Cli), "--pq-sigma must be >= 0 (got -1)");
        assert_eq!(e.to_string(), "pq_sigma must be >= 0 (got -1)");
    }

    /// A diagnosis tries the look-alikes outside the catalog unless the request turns them off
    /// (`--no-look-alikes`, `look_alikes=False`).
    #[test]
    fn a_diagnosis_tries_the_look_alikes_unless_asked_not_to() {
        let unit = crate::diagnose::trial::base_unit();
        assert!(
            DiagnoseRequest::default()
                .options(&unit)
                .unwrap()
                .look_alikes
        );
        let off = DiagnoseRequest {
            look_alikes: Some(false),
            ..Default::default()
        };
        assert!(!off.options(&unit).unwrap().look_alikes);
    }

    #[test]
    fn stages_parse_and_select_in_order() {
        let s = Stage::parse_list(&["tg, GEN"]).unwrap();
        assert_eq!(Stage::selection(&s).unwrap(), ["gen", "tg"]);
        assert_eq!(Stage::selection(&[Stage::Gen, Stage::All]), None);
        let e = Stage::parse_list(&["foo"]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "stages: unknown stage 'foo' (gen, avr, pss, tg or all)"
        );
        assert!(Stage::parse_list::<&str>(&[]).is_err());
    }

    #[test]
    fn stage_names_are_the_specs_stages_then_all() {
        assert_eq!(Stage::NAMES[..4], STAGES);
        for st in Stage::ALL {
            assert_eq!(st.name().parse::<Stage>().unwrap(), st);
        }
    }

    #[test]
    fn strategy_names_are_the_specs_names() {
        for st in Strategy::ALL {
            assert_eq!(st.name().parse::<Strategy>().unwrap(), st);
            let spec: crate::spec::CalibSpec = crate::spec::CalibSpec::parse(
                &format!("[calibration]\nstrategy = \"{}\"\n", st.name()),
                std::path::Path::new("spec.toml"),
            )
            .unwrap();
            assert_eq!(spec.strategy, st);
        }
        assert_eq!(
            "greedy".parse::<Strategy>().unwrap_err().to_string(),
            RequestError::new(
                "strategy",
                " must be 'sequential', 'incremental' or 'simultaneous-first' (got 'greedy')"
            )
            .to_string()
        );
    }

    #[test]
    fn strategies_and_methods_parse() {
        assert_eq!(
            "Simultaneous-First".parse::<Strategy>().unwrap(),
            Strategy::SimultaneousFirst
        );
        assert!("greedy".parse::<Strategy>().is_err());
        let bad = SimulateRequest {
            method: "rk4".into(),
            step: 0.0,
            ..Default::default()
        };
        assert_eq!(
            bad.options().unwrap_err().message(Style::Cli),
            "--step must be > 0 (got 0)"
        );
        let tol = SimulateRequest {
            atol: -1.0,
            ..Default::default()
        };
        assert_eq!(
            tol.options().unwrap_err().to_string(),
            "rtol must be > 0 and atol >= 0 (got rtol=0.000001, atol=-1)"
        );
        assert_eq!(
            SimulateRequest::default().options().unwrap().method,
            SimOptions::default().method
        );
    }

    #[test]
    fn hide_specs_parse() {
        let h = HideSpec::parse("measurement_skew:measurement.pq_delay_s=0.012").unwrap();
        assert_eq!(h.cause, "measurement_skew");
        assert_eq!(h.values, [("measurement.pq_delay_s".to_string(), 0.012)]);
        let e = HideSpec::parse("nope").unwrap_err();
        assert!(e
            .message(Style::Cli)
            .starts_with("--hide nope: unknown cause"));
        assert!(HideSpec::parse("measurement_skew:x=1,x=2").is_err());
        assert!(HideSpec::new("measurement_skew".into(), vec![("x".into(), f64::NAN)]).is_err());
    }

    #[test]
    fn refit_requests_parse() {
        assert_eq!(
            parse_refit("machine.h").unwrap(),
            ("machine.h".into(), None)
        );
        assert_eq!(
            parse_refit("exciter.k=50:200").unwrap(),
            ("exciter.k".into(), Some((50.0, 200.0)))
        );
        assert!(parse_refit("exciter.k=50")
            .unwrap_err()
            .message(Style::Cli)
            .starts_with("--refit exciter.k=50: no ':'"));
    }

    #[test]
    fn search_checks_particles_and_threads() {
        let s = Search {
            particles: Some(1),
            ..Default::default()
        };
        assert!(s.validate().unwrap_err().to_string().contains("particles"));
        let t = Search {
            threads: Some(0),
            ..Default::default()
        };
        assert_eq!(
            t.validate().unwrap_err().message(Style::Cli),
            "--threads must be at least 1"
        );
    }
}
