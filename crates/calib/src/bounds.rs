//! A free parameter with its bounds, and the one resolver that turns bounds into the
//! optimiser's coordinates ([`FreeParam`]) for the fit and for the diagnosis.
//!
//! [`FreeBound`] is what a calibration spec's `[[calibration.stage.free]]` tables hold, what a
//! diagnosis candidate frees (the catalog's causes, user cause files, `--refit`, a calibration's
//! whole calibrated set), and what [`resolve`] checks against a unit: the parameter exists, its
//! bounds are finite and not empty, and its start (given, or the unit's value) is clamped into
//! them.

use itaipu_dynamics::unit::Unit;
use serde::{Deserialize, Serialize};

use crate::problem::{FreeParam, Prior};

/// A free parameter with its bounds.
///
/// In a calibration spec (TOML) it is `{ param, min, max }` with optional `start` and `spread`;
/// any other key is refused. `scan`, `polish_only` and `prior` are set by the diagnosis.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FreeBound {
    /// `block.name`, e.g. `machine.x_d` (PSS/E aliases accepted: `machine.Xd`).
    pub param: String,
    pub min: f64,
    pub max: f64,
    /// Starting value; `None`: the value in the unit (clamped into the bounds).
    #[serde(default)]
    pub start: Option<f64>,
    /// Relative spread of this parameter's prior around the unit's value before the fit
    /// (overrides `calibration.prior`; 0 = no prior on it). Used by [`PriorSource::Datasheet`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spread: Option<f64>,
    /// Grid points to scan this parameter over before the swarm (0 = none): for a parameter
    /// whose objective has narrow valleys (a mode frequency, a delay, a limit that is hit or
    /// not), the best grid point becomes the start. A diagnosis setting (not a spec key).
    #[serde(skip_deserializing)]
    pub scan: usize,
    /// Held at its start during the global search and freed only in the final polish (for the
    /// calibrated parameters a diagnosis re-frees). A diagnosis setting (not a spec key).
    #[serde(skip_deserializing)]
    pub polish_only: bool,
    /// The prior of [`PriorSource::Given`]: a calibrated parameter's datasheet prior, so that a
    /// re-fit that bends it pays the same price as the calibration did.
    #[serde(skip)]
    pub prior: Option<Prior>,
}

impl FreeBound {
    /// `param` free within `[min, max]`, starting at the unit's value.
    pub fn new(param: impl Into<String>, min: f64, max: f64) -> Self {
        Self {
            param: param.into(),
            min,
            max,
            start: None,
            spread: None,
            scan: 0,
            polish_only: false,
            prior: None,
        }
    }

    /// The same bound starting at `start` clamped into `[min, max]` (not clamped when the
    /// bounds are not a range, which [`FreeBound::check`] reports wherever the bound is used).
    pub fn starting_at(self, start: f64) -> Self {
        Self {
            start: Some(clamp_into(start, self.min, self.max)),
            ..self
        }
    }

    /// The same bound starting at its value in `unit` (clamped), or at its own start (clamped)
    /// where `unit` lacks the parameter: a re-fit continuing from where another one ended.
    pub fn starting_in(&self, unit: &Unit) -> Self {
        match unit.param(&self.param) {
            Ok(r) => self.clone().starting_at(unit.get(r)),
            Err(_) => Self {
                start: self.start.map(|v| clamp_into(v, self.min, self.max)),
                ..self.clone()
            },
        }
    }

    /// The same bound scanned over `points` grid points before the swarm.
    pub fn scanned(self, points: usize) -> Self {
        Self {
            scan: points,
            ..self
        }
    }

    /// `param` of `unit` within its declared range ([`itaipu_dynamics::params::ParamSpec::range`],
    /// the plausible range), starting at its value clamped into it.
    pub fn declared(unit: &Unit, param: &str) -> Result<Self, BoundError> {
        let r = unit
            .param(param)
            .map_err(|e| BoundError::unknown(param, e))?;
        let (min, max) = unit.param_spec(r).range;
        let b = Self::new(unit.param_path(r), min, max);
        b.check()?;
        Ok(b.starting_at(unit.get(r)))
    }

    /// `param` of `unit` within `range` or, without, its declared range widened to hold its
    /// value, starting at its value (clamped); checked ([`FreeBound::check`]). A parsed request
    /// (`--refit PARAM[=MIN:MAX]`, a set-point offset) becomes a bound here.
    pub fn requested(
        unit: &Unit,
        param: &str,
        range: Option<(f64, f64)>,
    ) -> Result<Self, BoundError> {
        let r = unit
            .param(param)
            .map_err(|e| BoundError::unknown(param, e))?;
        let v = unit.get(r);
        let (min, max) = range.unwrap_or_else(|| {
            let (lo, hi) = unit.param_spec(r).range;
            (lo.min(v), hi.max(v))
        });
        let b = Self::new(unit.param_path(r), min, max);
        b.check()?;
        Ok(b.starting_at(v))
    }

    /// The start in a unit where the parameter's value is `value`: the given start or the
    /// value, clamped into the bounds (as [`FreeBound::starting_at`]).
    pub fn start_from(&self, value: f64) -> f64 {
        clamp_into(self.start.unwrap_or(value), self.min, self.max)
    }

    /// Checks the bounds alone: `min < max` (NaN fails it), both finite.
    pub fn check(&self) -> Result<(), BoundError> {
        let (min, max) = (self.min, self.max);
        if !(min < max) {
            return Err(BoundError::new(
                &self.param,
                BoundProblem::Empty { min, max },
            ));
        }
        if !(min.is_finite() && max.is_finite()) {
            return Err(BoundError::new(
                &self.param,
                BoundProblem::NonFinite { min, max },
            ));
        }
        Ok(())
    }
}

/// `v` clamped into `[min, max]`, or `v` itself when `[min, max]` is not a range (`min > max`
/// or a NaN bound, where `f64::clamp` panics): such a bound never resolves
/// ([`FreeBound::check`], [`resolve`]), and the error names it.
pub(crate) fn clamp_into(v: f64, min: f64, max: f64) -> f64 {
    if min <= max {
        v.clamp(min, max)
    } else {
        v
    }
}

/// Where a resolved parameter's prior comes from.
#[derive(Clone, Copy)]
pub enum PriorSource<'a> {
    /// Each bound's own [`FreeBound::prior`] (the diagnosis).
    Given,
    /// Around the parameter's value in `datasheet` (the unit before the fit), with the bound's
    /// [`FreeBound::spread`] or `default_spread` (the fit).
    Datasheet {
        datasheet: &'a Unit,
        default_spread: f64,
    },
}

/// The log-normal prior of `param` around its value in `datasheet` with `spread`; `None`
/// without one (no such parameter, a spread of 0, a non-positive value).
pub fn datasheet_prior(datasheet: &Unit, param: &str, spread: f64) -> Option<Prior> {
    datasheet
        .param(param)
        .ok()
        .map(|d| Prior {
            center: datasheet.get(d),
            spread,
        })
        .filter(|p| p.spread > 0.0 && p.center > 0.0)
}

/// Resolves `bounds` in `unit`: each parameter must exist and its bounds be finite and not
/// empty; its start (given or the unit's value) is clamped into them; its prior comes from
/// `priors`. The error names the parameter.
pub fn resolve(
    unit: &Unit,
    bounds: &[FreeBound],
    priors: PriorSource<'_>,
) -> Result<Vec<FreeParam>, BoundError> {
    bounds
        .iter()
        .map(|b| {
            let r = unit
                .param(&b.param)
                .map_err(|e| BoundError::unknown(&b.param, e))?;
            b.check()?;
            let prior = match priors {
                PriorSource::Given => b.prior,
                PriorSource::Datasheet {
                    datasheet,
                    default_spread,
                } => datasheet_prior(datasheet, &b.param, b.spread.unwrap_or(default_spread)),
            };
            Ok(FreeParam::new(
                unit.param_path(r),
                r,
                b.min,
                b.max,
                b.start.unwrap_or(unit.get(r)),
                unit.param_spec(r).unit,
            )
            .with_prior(prior))
        })
        .collect()
}

/// A bound that does not resolve: the parameter and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("free parameter {param}: {problem}")]
pub struct BoundError {
    pub param: String,
    pub problem: BoundProblem,
}

/// What is wrong with a bound.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoundProblem {
    /// The unit has no such parameter (the unit's message).
    #[error("{0}")]
    Unknown(String),
    /// A bound is NaN or infinite.
    #[error("bounds must be finite (got [{min}, {max}])")]
    NonFinite { min: f64, max: f64 },
    /// `min >= max`.
    #[error("bounds [{min}, {max}] are upside down or empty")]
    Empty { min: f64, max: f64 },
}

impl BoundError {
    fn new(param: &str, problem: BoundProblem) -> Self {
        Self {
            param: param.to_string(),
            problem,
        }
    }

    fn unknown(param: &str, why: impl std::fmt::Display) -> Self {
        Self::new(param, BoundProblem::Unknown(why.to_string()))
    }

    /// Short stable identifier of the problem (`"unknown"`, `"non_finite"`, `"empty"`).
    pub fn kind(&self) -> &'static str {
        match self.problem {
            BoundProblem::Unknown(_) => "unknown",
            BoundProblem::NonFinite { .. } => "non_finite",
            BoundProblem::Empty { .. } => "empty",
        }
    }
}
