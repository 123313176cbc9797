//! The calibration spec (TOML): which parameters are free in each stage, their bounds, the
//! objective, the window, the weights and the optimiser settings.
//!
//! It lives in a `[calibration]` table, either in the unit file or in a file of its own:
//!
//! ```toml
//! [calibration]
//! strategy = "sequential"        # "sequential" | "incremental" | "simultaneous-first"
//! seed = 1
//! polish = true                  # after several stages, a joint pass over all of them
//! stage_blocks = "keep"          # "keep" (whole unit in every stage) | "remove" (papers' reduction)
//! prior = 0.2                    # spread of the prior around the unit's values (0 = none)
//! local = "lm"                   # local method after each swarm: "lm" | "lbfgs"
//! [calibration.pso]              # optional, defaults shown
//! particles = 40
//! iterations = 100
//! [calibration.lbfgs]            # the local method's settings (either method)
//! iterations = 100
//!
//! [[calibration.stage]]
//! name = "gen"                   # gen | avr | pss | tg
//! objective = "pq"               # pq (paper 000 eq. 3) | q (paper 001 eq. 4) | p
//! weights = { p = 1.0, q = 1.0 } # optional
//! window = [0.0, 4.65]           # optional; default: the event's fit window
//! lowpass_hz = 15.0              # optional zero-phase low-pass of the measurement
//! set = { "machine.x_l" = 0.13 } # optional fixed values, applied before this stage and kept
//! free = [ { param = "machine.x_d", min = 0.6, max = 2.0 }, … ]   # in engineering order
//!                                # optional per parameter: start = …, spread = … (prior)
//! [calibration.stage.replace.governor]   # optional: a block put into the unit from this stage on
//! model = "HYGOV"
//! r_perm = 0.05                  # …every parameter, as in a unit file
//!
//! [[calibration.stage]]          # a stage on a record without an angle names its playback mode
//! name = "avr"
//! mode = "exciter_alone"         # phasor (default) | exciter_alone | machine_from_efd | closed_loop
//! channels = { efd = 1.0 }       # compared channels and weights; default: the mode's, weight 1
//! free = [ … ]
//!
//! [calibration.joint]            # optional: how the joint pass plays the record back
//!                                # (default: what the stages compared, CalibSpec::joint_compare_of)
//! mode = "closed_loop"
//! channels = { v = 1.0, q = 1.0, efd = 1.0 }   # a phasor pass: also "recorded" (P, Q and the
//!                                # recorded field weighted by their noise: Channels::Recorded)
//! free = [ { param = "grid.x_e", min = 0.02, max = 0.5 } ]   # freed in the joint pass only
//! ```
//!
//! **Playback modes and channels** (`itaipu_dynamics::mode`). A stage's `mode` says how the
//! record is played back; `channels` which simulated channels (`p`, `q`, `v`, `efd`, `ifd`) it
//! compares with the record, each with its weight. The objective is RaPId's: the weighted sum
//! over the window's samples and the channels of the squared differences in per unit, equal
//! weights by default (a channel's noise does not scale it; give weights to do so). A phasor
//! stage without `channels` keeps `objective` and `weights` (P and Q), the same numbers as
//! before; `objective` and `weights` do not go with `channels` or another mode. A channel the
//! mode imposes from the record (P in the P-held modes, |V| everywhere but `closed_loop`) cannot
//! be compared.
//!
//! Stage semantics (paper 001 Phase A-C, paper 000 Algorithm 1): stages run in the order gen,
//! avr, pss, tg, each freeing its parameters with earlier stages' results frozen. With
//! `stage_blocks = "keep"` (default) every stage simulates the whole unit, later stages' blocks at
//! their current values; with `stage_blocks = "remove"` (the papers' reduction) `gen` simulates the
//! machine with E_fd held at E_fd0 and P_m constant (exciter, PSS and governor removed), `avr` adds
//! the exciter, `pss` the stabiliser, `tg` the governor.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Channel;
use itaipu_dynamics::mode::PlaybackMode;
use serde::Deserialize;

use crate::bounds::FreeBound;

/// Stage names in their fixed order.
pub const STAGES: [&str; 4] = ["gen", "avr", "pss", "tg"];

/// What a stage does with the blocks of later stages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StageBlocks {
    /// Every block stays in the unit at its current values: a stage fits its parameters on the
    /// unit that produced the record (the default: on a record longer than a few seconds the
    /// AVR, PSS and governor act, and a unit without them cannot reproduce it, so its fitted
    /// parameters bend to make up for them).
    #[default]
    Keep,
    /// The paper's reduction: the generator stage holds E_fd at E_fd0 and P_m constant
    /// (exciter, PSS and governor removed), the AVR stage adds the exciter, and so on
    /// ([`removed_blocks`]). Right for a record short enough that the controls barely act.
    Remove,
}

/// Blocks removed from the unit in each stage under [`StageBlocks::Remove`].
pub fn removed_blocks(stage: &str) -> &'static [&'static str] {
    match stage {
        "gen" => &["exciter", "pss", "governor"],
        "avr" => &["pss", "governor"],
        "pss" => &["governor"],
        _ => &[],
    }
}

/// How stages are combined (paper 000 Algorithm 1; paper 001 Fig. 10 and "simultaneous-first").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// Each stage: PSO over the stage's parameters, then L-BFGS from the PSO best.
    Sequential,
    /// In the generator stage, free the parameters one at a time in the listed (engineering)
    /// order, each step an L-BFGS run from the last; other stages as `sequential`.
    Incremental,
    /// PSO + L-BFGS over all stages' parameters at once on the full unit, then the sequential
    /// pass starting from that result.
    SimultaneousFirst,
}

impl Strategy {
    /// The names, as in the spec (serde's kebab-case names; a test ties the two), on the
    /// command line and in Python, in the order of [`Strategy::ALL`].
    pub const NAMES: [&'static str; 3] = ["sequential", "incremental", "simultaneous-first"];

    /// Every strategy, in the order of [`Strategy::NAMES`].
    pub const ALL: [Strategy; 3] = [
        Strategy::Sequential,
        Strategy::Incremental,
        Strategy::SimultaneousFirst,
    ];

    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What the objective sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Objective {
    /// Σ w_p ΔP² + w_q ΔQ² (paper 000 eq. 3, RaPId's J).
    Pq,
    /// Σ ΔQ² (paper 001 eq. 4, used for the AVR and PSS stages).
    Q,
    /// Σ ΔP².
    P,
}

/// Signal weights.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Weights {
    #[serde(default = "one")]
    pub p: f64,
    #[serde(default = "one")]
    pub q: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for Weights {
    fn default() -> Self {
        Self { p: 1.0, q: 1.0 }
    }
}

/// One stage.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageSpec {
    pub name: String,
    #[serde(default = "default_objective")]
    pub objective: Objective,
    #[serde(default)]
    pub weights: Weights,
    pub window: Option<[f64; 2]>,
    pub lowpass_hz: Option<f64>,
    #[serde(default)]
    pub set: BTreeMap<String, f64>,
    #[serde(default)]
    pub free: Vec<FreeBound>,
    /// Tied parameters `to = from`: `to` takes `from`'s value in every candidate (e.g.
    /// `"machine.x_q_pp" = "machine.x_d_pp"` for a machine whose data give one X'').
    #[serde(default)]
    pub tie: BTreeMap<String, String>,
    /// Blocks put into the unit from this stage on (section name → unit-file table).
    #[serde(default)]
    pub replace: BTreeMap<String, toml::Table>,
    /// How the record is played back in this stage (default: the phasor playback).
    #[serde(default)]
    pub mode: PlaybackMode,
    /// Compared channels and their weights (`{ efd = 1.0 }`), or `"recorded"` (phasor
    /// playback: [`Channels::Recorded`]); default: the mode's
    /// ([`PlaybackMode::default_channels`], weight 1). A phasor stage without it compares P and
    /// Q as `objective` and `weights` say.
    #[serde(default)]
    pub channels: Option<Channels>,
}

/// What a stage (or the joint pass) says it compares: `channels = { p = 1.0, efd = 0.04 }` or
/// `channels = "recorded"`.
#[derive(Debug, Clone, PartialEq)]
pub enum Channels {
    /// Channel name → weight.
    Weights(BTreeMap<String, f64>),
    /// The phasor playback's P and Q (weight 1) and every field channel
    /// ([`crate::diagnose::playback::FIELD_CHANNELS`]: E_fd, X_ad I_fd) that every event of the
    /// fit records, each weighted by its inverse noise variance against P's and Q's
    /// ([`crate::noise::field_weights`]): the likelihood of independent Gaussian noise, so a
    /// field channel five times noisier than P counts 1/25 as much per sample. The choice an
    /// engineer with the excitation system's recorder makes: P and Q alone leave X_d and the
    /// exciter's gain free to bend until the field runs off the recorded one by many noise
    /// widths. Resolved against the events when the fit starts
    /// ([`CalibSpec::resolve_recorded`]); with no field channel recorded, the stage compares P
    /// and Q as a stage without `channels` does (the same numbers).
    Recorded,
}

impl Channels {
    /// The weights by channel name (`None` for an unresolved [`Channels::Recorded`]).
    pub fn weights(&self) -> Option<&BTreeMap<String, f64>> {
        match self {
            Channels::Weights(m) => Some(m),
            Channels::Recorded => None,
        }
    }
}

impl<'de> Deserialize<'de> for Channels {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Channels;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of channel weights ({ p = 1.0, efd = 0.04 }) or \"recorded\"")
            }
            fn visit_str<E: serde::de::Error>(self, s: &str) -> Result<Channels, E> {
                if s == "recorded" {
                    Ok(Channels::Recorded)
                } else {
                    Err(E::invalid_value(serde::de::Unexpected::Str(s), &self))
                }
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, m: A) -> Result<Channels, A::Error> {
                BTreeMap::deserialize(serde::de::value::MapAccessDeserializer::new(m))
                    .map(Channels::Weights)
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// What a stage compares when it names a mode or channels: the mode and `(channel, weight)`
/// pairs with a non-zero weight, in canonical channel order.
#[derive(Debug, Clone, PartialEq)]
pub struct Compare {
    pub mode: PlaybackMode,
    pub weights: Vec<(Channel, f64)>,
}

impl Compare {
    /// The compared channels and weights of `mode` with `channels` (names checked by
    /// [`CalibSpec::parse`]; unknown names are left out here).
    pub fn new(mode: PlaybackMode, channels: Option<&BTreeMap<String, f64>>) -> Compare {
        let weights = match channels {
            None => mode.default_channels().iter().map(|c| (*c, 1.0)).collect(),
            Some(m) => Channel::ALL
                .into_iter()
                .filter_map(|c| m.get(c.name()).map(|w| (c, *w)))
                .filter(|(_, w)| *w > 0.0)
                .collect(),
        };
        Compare { mode, weights }
    }

    /// The channels compared.
    pub fn channels(&self) -> Vec<Channel> {
        self.weights.iter().map(|(c, _)| *c).collect()
    }

    /// `"mode: v 1, q 1, efd 1"`, for reports.
    pub fn describe(&self) -> String {
        format!(
            "{}: {}",
            self.mode,
            self.weights
                .iter()
                .map(|(c, w)| format!("{c} {w}"))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

impl StageSpec {
    /// What the stage compares: `None` for a phasor stage without `channels` (P and Q by
    /// `objective` and `weights`, the historical objective), else the mode and its channels.
    /// An unresolved `channels = "recorded"` (before [`CalibSpec::resolve_recorded`]) reads as
    /// P and Q: nothing it may compare is required of an event.
    pub fn compare(&self) -> Option<Compare> {
        let weights = self.channels.as_ref().and_then(Channels::weights);
        if self.mode == PlaybackMode::Phasor && weights.is_none() {
            None
        } else {
            Some(Compare::new(self.mode, weights))
        }
    }
}

/// How the joint pass (and a simultaneous-first pass) plays the record back, and what it frees
/// besides the stages' parameters (`[calibration.joint]`).
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    #[serde(default)]
    pub mode: PlaybackMode,
    #[serde(default)]
    pub channels: Option<Channels>,
    /// Parameters freed in the joint pass only (a grid equivalent's impedance, say).
    #[serde(default)]
    pub free: Vec<FreeBound>,
    pub window: Option<[f64; 2]>,
}

fn default_objective() -> Objective {
    Objective::Pq
}

/// PSO settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PsoSpec {
    #[serde(default = "default_particles")]
    pub particles: usize,
    #[serde(default = "default_pso_iterations")]
    pub iterations: usize,
    /// Starts of the local method after a stage's swarm (its best and other distinct particles'
    /// bests), at least 1.
    #[serde(default = "default_local_starts")]
    pub local_starts: usize,
    /// Swarm iterations of the joint pass (every freed parameter on the full unit); `None`:
    /// `iterations`.
    #[serde(default)]
    pub joint_iterations: Option<usize>,
}

/// Swarm size of a stage when the spec does not say.
pub const DEFAULT_PARTICLES: usize = 40;
/// Swarm iterations of a stage (and of the joint pass, unless `joint_iterations` says) when the
/// spec does not say.
pub const DEFAULT_PSO_ITERATIONS: usize = 100;
/// Local-method iterations of a stage when the spec does not say (`[calibration.lbfgs]
/// iterations`: the table keeps its historical name; it caps Levenberg-Marquardt too).
pub const DEFAULT_LOCAL_ITERATIONS: u64 = 100;
/// Starts of the local method after a stage's swarm when the spec does not say: the swarm's best
/// alone. A short swarm with several starts (`iterations = 35`, `local_starts = 4`,
/// `joint_iterations = 100`) fits faster at about the same J, but a shorter swarm lands more
/// often in a valley a longer one leaves, where a clean record can look like a missing cause
/// to the diagnosis: not the default.
pub const DEFAULT_LOCAL_STARTS: usize = 1;
/// Swarm seed when the spec does not say.
pub const DEFAULT_SEED: u64 = 1;

fn default_particles() -> usize {
    DEFAULT_PARTICLES
}
fn default_pso_iterations() -> usize {
    DEFAULT_PSO_ITERATIONS
}
fn default_local_starts() -> usize {
    DEFAULT_LOCAL_STARTS
}

impl Default for PsoSpec {
    fn default() -> Self {
        Self {
            particles: default_particles(),
            iterations: default_pso_iterations(),
            local_starts: default_local_starts(),
            joint_iterations: None,
        }
    }
}

/// L-BFGS settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LbfgsSpec {
    #[serde(default = "default_lbfgs_iterations")]
    pub iterations: u64,
    #[serde(default = "default_memory")]
    pub memory: usize,
}

fn default_lbfgs_iterations() -> u64 {
    DEFAULT_LOCAL_ITERATIONS
}
fn default_memory() -> usize {
    7
}

impl Default for LbfgsSpec {
    fn default() -> Self {
        Self {
            iterations: default_lbfgs_iterations(),
            memory: default_memory(),
        }
    }
}

/// The whole spec.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibSpec {
    #[serde(default = "default_strategy")]
    pub strategy: Strategy,
    #[serde(default = "default_seed")]
    pub seed: u64,
    #[serde(default)]
    pub pso: PsoSpec,
    #[serde(default)]
    pub lbfgs: LbfgsSpec,
    #[serde(default, rename = "stage")]
    pub stages: Vec<StageSpec>,
    /// After several stages, refine all their parameters together on the full unit.
    #[serde(default = "default_polish")]
    pub polish: bool,
    /// What a stage does with the blocks of later stages (`keep` or `remove`).
    #[serde(default)]
    pub stage_blocks: StageBlocks,
    /// Default relative spread of the log-normal prior that ties each free (positive) parameter
    /// to the unit's value before the fit, the datasheet value (`crate::problem::Prior`); 0 = no
    /// prior.
    #[serde(default = "default_prior")]
    pub prior: f64,
    /// The local method after each swarm (`lm` or `lbfgs`).
    #[serde(default)]
    pub local: LocalMethod,
    /// How the joint pass plays the record back (`[calibration.joint]`; default: the phasor
    /// playback comparing what the stages compared, [`CalibSpec::joint_compare_of`]).
    #[serde(default)]
    pub joint: Option<JointSpec>,
}

/// The local (gradient) method after the swarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LocalMethod {
    /// Levenberg-Marquardt on the residual Jacobian ([`crate::local::levenberg_marquardt`]):
    /// the objective is a sum of squares, and the Gauss-Newton model follows the long curved
    /// valleys of 20-odd correlated parameters where L-BFGS on the sum stalls.
    #[default]
    Lm,
    /// argmin's L-BFGS on the sum of squares ([`crate::local::refine`]).
    Lbfgs,
}

impl LocalMethod {
    /// The method's name as the front ends print it.
    pub fn describe(self) -> &'static str {
        match self {
            LocalMethod::Lm => "Levenberg-Marquardt",
            LocalMethod::Lbfgs => "L-BFGS",
        }
    }
}

/// How a stage's parameters are searched, in the words `fit --help`, the Python docstrings and
/// the reports use: the swarm, then the default local method ([`LocalMethod::default`]).
pub const SEARCH_METHOD: &str =
    "a parallel particle swarm, then Levenberg-Marquardt (L-BFGS with local = \"lbfgs\")";

/// Default prior spread: a datasheet or commissioning value trusted to about 20 % (one
/// standard deviation of `ln x`); a 50 % error then costs about 4 in χ², what the data pay for
/// a fraction of a percent of their misfit.
pub const DEFAULT_PRIOR_SPREAD: f64 = 0.2;

fn default_prior() -> f64 {
    DEFAULT_PRIOR_SPREAD
}

fn default_polish() -> bool {
    true
}

fn default_strategy() -> Strategy {
    Strategy::Sequential
}
fn default_seed() -> u64 {
    DEFAULT_SEED
}

#[derive(Deserialize)]
struct FileWithCalibration {
    calibration: Option<CalibSpec>,
}

/// Error reading a calibration spec. Messages name the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {msg}", path.display())]
    Syntax { path: PathBuf, msg: String },
    #[error("{}: no [calibration] table (give one in the unit file or with --calib)", path.display())]
    Missing { path: PathBuf },
    #[error("{}: {field}: {msg}", path.display())]
    Field {
        path: PathBuf,
        field: String,
        msg: String,
    },
}

impl SpecError {
    /// Short stable identifier of the variant (`"io"`, `"syntax"`, `"missing"`, `"field"`).
    pub fn kind(&self) -> &'static str {
        match self {
            SpecError::Io { .. } => "io",
            SpecError::Syntax { .. } => "syntax",
            SpecError::Missing { .. } => "missing",
            SpecError::Field { .. } => "field",
        }
    }
}

impl CalibSpec {
    /// Reads the `[calibration]` table of a file.
    pub fn from_file(path: &Path) -> Result<CalibSpec, SpecError> {
        let text = std::fs::read_to_string(path).map_err(|e| SpecError::Io {
            path: path.into(),
            source: e,
        })?;
        Self::parse(&text, path)
    }

    /// Parses text (`path` is used in messages).
    pub fn parse(text: &str, path: &Path) -> Result<CalibSpec, SpecError> {
        let f: FileWithCalibration = toml::from_str(text).map_err(|e| SpecError::Syntax {
            path: path.into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
        let mut spec = f
            .calibration
            .ok_or_else(|| SpecError::Missing { path: path.into() })?;
        spec.validate(path)?;
        check_objective_keys(text, path)?;
        // A replacement diagram's definition file is relative to the spec's file.
        let base = path.parent().unwrap_or(Path::new(""));
        for s in &mut spec.stages {
            for t in s.replace.values_mut() {
                if let Some(toml::Value::String(file)) = t.get_mut("diagram") {
                    if Path::new(file.as_str()).is_relative() {
                        *file = base.join(file.as_str()).to_string_lossy().into_owned();
                    }
                }
            }
        }
        Ok(spec)
    }

    fn validate(&self, path: &Path) -> Result<(), SpecError> {
        let err = |field: String, msg: String| SpecError::Field {
            path: path.into(),
            field,
            msg,
        };
        if !(self.prior >= 0.0 && self.prior.is_finite()) {
            return Err(err(
                "calibration.prior".into(),
                format!("must be a finite spread >= 0 (got {})", self.prior),
            ));
        }
        if self.pso.particles < 2 {
            return Err(err(
                "calibration.pso.particles".into(),
                "needs at least 2".into(),
            ));
        }
        if self.pso.local_starts < 1 {
            return Err(err(
                "calibration.pso.local_starts".into(),
                "needs at least 1 (the swarm's best)".into(),
            ));
        }
        let mut last = None;
        for (k, s) in self.stages.iter().enumerate() {
            let ctx = format!("calibration.stage[{k}]");
            let pos = STAGES.iter().position(|n| *n == s.name).ok_or_else(|| {
                err(
                    format!("{ctx}.name"),
                    format!("'{}' is not one of gen, avr, pss, tg", s.name),
                )
            })?;
            if last.is_some_and(|l| pos <= l) {
                return Err(err(
                    format!("{ctx}.name"),
                    "stages must be listed once each, in the order gen, avr, pss, tg".into(),
                ));
            }
            last = Some(pos);
            if let Some([a, b]) = s.window {
                if !(a < b) {
                    return Err(err(
                        format!("{ctx}.window"),
                        format!("start {a} must be before end {b}"),
                    ));
                }
            }
            if let Some(fc) = s.lowpass_hz {
                if !(fc > 0.0) {
                    return Err(err(
                        format!("{ctx}.lowpass_hz"),
                        format!("must be > 0 (got {fc})"),
                    ));
                }
            }
            if !(s.weights.p >= 0.0
                && s.weights.q >= 0.0
                && s.weights.p.is_finite()
                && s.weights.q.is_finite())
            {
                return Err(err(
                    format!("{ctx}.weights"),
                    "weights must be finite and >= 0".into(),
                ));
            }
            // The objective sums only the signals it names, each with its weight: with every
            // one of those weights zero there is nothing to fit (no residual at all).
            let (wp, wq) = match s.objective {
                Objective::Pq => (s.weights.p, s.weights.q),
                Objective::P => (s.weights.p, 0.0),
                Objective::Q => (0.0, s.weights.q),
            };
            if wp == 0.0 && wq == 0.0 {
                let (field, what) = match s.objective {
                    Objective::Pq => ("weights", "weights p and q are both 0"),
                    Objective::P => ("weights.p", "objective \"p\" with weight p = 0"),
                    Objective::Q => ("weights.q", "objective \"q\" with weight q = 0"),
                };
                return Err(err(
                    format!("{ctx}.{field} (stage {})", s.name),
                    format!(
                        "{what}: the stage's objective would sum nothing; give the signal \
                         a weight > 0 or change the objective"
                    ),
                ));
            }
            check_channels(
                &err,
                &format!("{ctx}.channels (stage {})", s.name),
                s.mode,
                s.channels.as_ref(),
            )?;
            check_free(&err, &ctx, &s.free)?;
        }
        if let Some(j) = &self.joint {
            check_channels(
                &err,
                "calibration.joint.channels",
                j.mode,
                j.channels.as_ref(),
            )?;
            check_free(&err, "calibration.joint", &j.free)?;
            if let Some([a, b]) = j.window {
                if !(a < b) {
                    return Err(err(
                        "calibration.joint.window".into(),
                        format!("start {a} must be before end {b}"),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Whether a stage or the joint pass says `channels = "recorded"`.
    pub fn compares_recorded(&self) -> bool {
        self.stages
            .iter()
            .map(|s| &s.channels)
            .chain(self.joint.as_ref().map(|j| &j.channels))
            .any(|c| c == &Some(Channels::Recorded))
    }

    /// The spec with every `channels = "recorded"` ([`Channels::Recorded`]) made the weights of
    /// the fitted `events`: P and Q at 1 and each field channel every event (fitted and
    /// `held_out`) records at [`crate::noise::field_weights`]; with none recorded, no `channels`
    /// (P and Q by the stage's `objective` and `weights`, the historical objective and its
    /// numbers).
    pub fn resolve_recorded(
        &self,
        events: &[&itaipu_dynamics::event::Event],
        held_out: &[&itaipu_dynamics::event::Event],
    ) -> CalibSpec {
        let field = crate::noise::field_weights(events, held_out);
        let resolved = || -> Option<Channels> {
            (!field.is_empty()).then(|| {
                let mut m = BTreeMap::from([("p".to_string(), 1.0), ("q".to_string(), 1.0)]);
                m.extend(field.iter().map(|(c, w)| (c.name().to_string(), *w)));
                Channels::Weights(m)
            })
        };
        let mut out = self.clone();
        for c in out
            .stages
            .iter_mut()
            .map(|s| &mut s.channels)
            .chain(out.joint.iter_mut().map(|j| &mut j.channels))
        {
            if *c == Some(Channels::Recorded) {
                *c = resolved();
            }
        }
        out
    }

    /// What the joint (and simultaneous) pass compares when every stage of the spec runs
    /// ([`CalibSpec::joint_compare_of`]).
    pub fn joint_compare(&self) -> Option<Compare> {
        let all: Vec<String> = self.stages.iter().map(|s| s.name.clone()).collect();
        self.joint_compare_of(&all)
    }

    /// What the joint (and simultaneous) pass of a fit of `stages` compares; `None`: P and Q at
    /// weight 1 (the historical joint pass).
    ///
    /// `[calibration.joint]` decides when it says what to compare (`channels`, or a mode other
    /// than the phasor playback, whose default channels it then compares). Otherwise the joint
    /// pass compares what its stages compared: the union of the stages' channels that the phasor
    /// playback simulates ([`PlaybackMode::outputs`]: |V|, which it imposes, is left out), a
    /// stage without `channels` counting as P and Q at weight 1. A joint pass on P and Q alone
    /// after stages that fitted the field would undo their field fit (the exciter's gain and
    /// X_d bend back to wherever P and Q alone put them), which no report would show.
    ///
    /// A channel that stages weigh differently takes the **largest** weight any of them gave
    /// it. A weight says how much a channel is trusted against the others, which is a property
    /// of its noise, the same in every pass (`channels = "recorded"` gives every stage the same
    /// weights); a smaller weight in another stage is that stage's emphasis on its own channels,
    /// and the stage that weighed the channel most is the one whose parameters it determines
    /// (the AVR stage's E_fd): the joint pass must not let those drift on a channel that counts
    /// less there than where they were fitted.
    pub fn joint_compare_of(&self, stages: &[String]) -> Option<Compare> {
        if let Some(j) = &self.joint {
            match (&j.channels, j.mode) {
                // Unresolved (before `resolve_recorded`): P and Q, nothing required of an event.
                (Some(Channels::Recorded), _) => return None,
                (Some(Channels::Weights(w)), m) => return Some(Compare::new(m, Some(w))),
                (None, m) if m != PlaybackMode::Phasor => return Some(Compare::new(m, None)),
                (None, _) => {}
            }
        }
        let mut union: Vec<(Channel, f64)> = vec![];
        let mut add = |c: Channel, w: f64| {
            if !PlaybackMode::Phasor.outputs().contains(&c) || !(w > 0.0) {
                return;
            }
            match union.iter_mut().find(|(x, _)| *x == c) {
                Some((_, v)) => *v = v.max(w),
                None => union.push((c, w)),
            }
        };
        for st in stages.iter().filter_map(|s| self.stage(s)) {
            match st.compare() {
                Some(c) => c.weights.into_iter().for_each(|(c, w)| add(c, w)),
                None => {
                    add(Channel::P, 1.0);
                    add(Channel::Q, 1.0);
                }
            }
        }
        union.sort_by_key(|(c, _)| *c);
        (union != [(Channel::P, 1.0), (Channel::Q, 1.0)] && !union.is_empty()).then_some(Compare {
            mode: PlaybackMode::Phasor,
            weights: union,
        })
    }

    /// Every distinct comparison the fit of `stages` makes (the stages', then the joint
    /// pass's when it runs): the playback modes a fit's fitness rows report. Empty when every
    /// stage is a historical phasor P+Q stage.
    pub fn compares(&self, stages: &[String], joint: bool) -> Vec<Compare> {
        let mut out: Vec<Compare> = vec![];
        let legacy = Compare::new(PlaybackMode::Phasor, None);
        let mut any_mode = false;
        let mut push = |c: Compare| {
            if let Some(e) = out.iter_mut().find(|e| e.mode == c.mode) {
                for (ch, w) in c.weights {
                    if !e.weights.iter().any(|(x, _)| *x == ch) {
                        e.weights.push((ch, w));
                    }
                }
                e.weights.sort_by_key(|(c, _)| *c);
            } else {
                out.push(c);
            }
        };
        for s in stages {
            match self.stage(s).map(|st| st.compare()) {
                Some(Some(c)) => {
                    any_mode = true;
                    push(c)
                }
                Some(None) => push(legacy.clone()),
                None => {}
            }
        }
        if joint {
            if let Some(c) = self.joint_compare_of(stages) {
                any_mode = true;
                push(c);
            }
        }
        if any_mode {
            out
        } else {
            vec![]
        }
    }
}

/// Checks a stage's (or the joint pass's) `channels` against its mode.
fn check_channels(
    err: &dyn Fn(String, String) -> SpecError,
    field: &str,
    mode: PlaybackMode,
    channels: Option<&Channels>,
) -> Result<(), SpecError> {
    let m = match channels {
        None => return Ok(()),
        Some(Channels::Recorded) if mode != PlaybackMode::Phasor => {
            return Err(err(
                field.to_string(),
                format!(
                    "\"recorded\" goes with the phasor playback (P, Q and the recorded field); \
                     mode {mode} names its channels with weights, {{ efd = 1.0 }}"
                ),
            ))
        }
        Some(Channels::Recorded) => return Ok(()),
        Some(Channels::Weights(m)) => m,
    };
    let outputs = mode.outputs();
    let names = |cs: &[Channel]| cs.iter().map(|c| c.name()).collect::<Vec<_>>().join(", ");
    for (name, w) in m {
        let Some(c) = Channel::parse(name) else {
            return Err(err(
                field.to_string(),
                format!(
                    "unknown channel '{name}' (channels a mode can compare: p, q, v, efd, ifd)"
                ),
            ));
        };
        if !outputs.contains(&c) {
            return Err(err(
                format!("{field}.{name}"),
                format!(
                    "mode {mode} does not simulate {c} (it plays it back from the record or \
                     has no such output); it can compare: {}",
                    names(outputs)
                ),
            ));
        }
        if !(w.is_finite() && *w >= 0.0) {
            return Err(err(
                format!("{field}.{name}"),
                format!("weight {w} must be finite and >= 0"),
            ));
        }
    }
    if !m.values().any(|w| *w > 0.0) {
        return Err(err(
            field.to_string(),
            "no channel with a weight > 0: the objective would sum nothing".into(),
        ));
    }
    Ok(())
}

/// Checks a list of free entries (`ctx`: `calibration.stage[k]` or `calibration.joint`).
fn check_free(
    err: &dyn Fn(String, String) -> SpecError,
    ctx: &str,
    free: &[FreeBound],
) -> Result<(), SpecError> {
    {
        {
            for (j, f) in free.iter().enumerate() {
                let fctx = format!("{ctx}.free[{j}] ({})", f.param);
                if !(f.min.is_finite() && f.max.is_finite()) {
                    return Err(err(fctx, "bounds must be finite".into()));
                }
                if !(f.min < f.max) {
                    return Err(err(
                        fctx,
                        format!(
                            "bounds upside down or empty: min {} >= max {}",
                            f.min, f.max
                        ),
                    ));
                }
                if let Some(x) = f.start {
                    if !(x >= f.min && x <= f.max) {
                        return Err(err(
                            fctx,
                            format!("start {x} lies outside [{}, {}]", f.min, f.max),
                        ));
                    }
                }
                if let Some(sp) = f.spread {
                    if !(sp >= 0.0 && sp.is_finite()) {
                        return Err(err(
                            fctx,
                            format!("spread must be a finite number >= 0 (got {sp})"),
                        ));
                    }
                }
                if free[..j].iter().any(|g| g.param == f.param) {
                    return Err(err(fctx, "listed twice".into()));
                }
            }
        }
    }
    Ok(())
}

/// `objective` and `weights` say what a phasor stage compares (P and Q); with `channels` or
/// another mode they would be ignored: refused, naming the stage.
fn check_objective_keys(text: &str, path: &Path) -> Result<(), SpecError> {
    let Ok(doc) = text.parse::<toml::Table>() else {
        return Ok(());
    };
    let stages = doc
        .get("calibration")
        .and_then(|c| c.get("stage"))
        .and_then(|s| s.as_array());
    for (k, st) in stages.into_iter().flatten().enumerate() {
        let Some(t) = st.as_table() else { continue };
        let moded = t.contains_key("channels")
            || t.get("mode")
                .and_then(|m| m.as_str())
                .is_some_and(|m| m != "phasor");
        if !moded {
            continue;
        }
        for key in ["objective", "weights"] {
            if t.contains_key(key) {
                return Err(SpecError::Field {
                    path: path.into(),
                    field: format!("calibration.stage[{k}].{key}"),
                    msg: "goes with a phasor stage's P and Q; a stage with a mode or channels \
                          says what it compares with channels = { … } (weights per channel)"
                        .into(),
                });
            }
        }
    }
    Ok(())
}

impl CalibSpec {
    /// The blocks stage `stage` removes from the unit (none under [`StageBlocks::Keep`]).
    pub fn removed_blocks(&self, stage: &str) -> &'static [&'static str] {
        match self.stage_blocks {
            StageBlocks::Keep => &[],
            StageBlocks::Remove => removed_blocks(stage),
        }
    }

    /// The spec of stage `name`, if listed.
    pub fn stage(&self, name: &str) -> Option<&StageSpec> {
        self.stages.iter().find(|s| s.name == name)
    }
}

#[cfg(test)]
mod search_method_tests {
    use super::*;

    #[test]
    fn the_search_method_names_the_default_local_method_first() {
        let after_swarm = SEARCH_METHOD.split("then ").nth(1).unwrap_or_default();
        assert!(
            after_swarm.starts_with(LocalMethod::default().describe()),
            "{SEARCH_METHOD}"
        );
    }
}
