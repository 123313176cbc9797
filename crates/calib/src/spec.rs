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
//! ```
//!
//! Stage semantics (paper 001 Phase A-C, paper 000 Algorithm 1): stages run in the order gen,
//! avr, pss, tg, each freeing its parameters with earlier stages' results frozen. With
//! `stage_blocks = "keep"` (default) every stage simulates the whole unit, later stages' blocks at
//! their current values; with `stage_blocks = "remove"` (the papers' reduction) `gen` simulates the
//! machine with E_fd held at E_fd0 and P_m constant (exciter, PSS and governor removed), `avr` adds
//! the exciter, `pss` the stabiliser, `tg` the governor.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
}

/// Swarm size of a stage when the spec does not say.
pub const DEFAULT_PARTICLES: usize = 40;
/// Swarm iterations of a stage when the spec does not say.
pub const DEFAULT_PSO_ITERATIONS: usize = 100;
/// Local-method iterations of a stage when the spec does not say (`[calibration.lbfgs]
/// iterations`: the table keeps its historical name; it caps Levenberg-Marquardt too).
pub const DEFAULT_LOCAL_ITERATIONS: u64 = 100;
/// Swarm seed when the spec does not say.
pub const DEFAULT_SEED: u64 = 1;

fn default_particles() -> usize {
    DEFAULT_PARTICLES
}
fn default_pso_iterations() -> usize {
    DEFAULT_PSO_ITERATIONS
}

impl Default for PsoSpec {
    fn default() -> Self {
        Self {
            particles: default_particles(),
            iterations: default_pso_iterations(),
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
            for (j, f) in s.free.iter().enumerate() {
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
                if s.free[..j].iter().any(|g| g.param == f.param) {
                    return Err(err(fctx, "listed twice".into()));
                }
            }
        }
        Ok(())
    }

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
