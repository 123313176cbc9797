//! The calibrated parameters a diagnosis frees again in every re-fit
//! ([`super::DiagnoseOptions::refit`]): a fit's calibrated set, the parameters a user names,
//! and their check against the unit.

use itaipu_dynamics::unit::Unit;

use crate::bounds::{clamp_into, datasheet_prior, BoundError, FreeBound};

use super::error::DiagnoseError;

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
            out.push(FreeBound {
                prior: datasheet_prior(datasheet, &param, spread),
                param,
                min: f.min,
                max: f.max,
                // A spec built in code may hold an upside-down bound (a parsed one cannot):
                // kept as it is, `diagnose` refuses it by name (`check_refit`).
                start: Some(clamp_into(calibrated.get(r), f.min, f.max)),
                spread: None,
                scan: 0,
                polish_only: true,
            });
        }
    }
    out
}

/// Adds a fit's calibrated set to the re-fit bounds: each parameter the request did not name
/// already, and that the unit has.
pub fn merge_calibrated_set(refit: &mut Vec<FreeBound>, set: &[FreeBound], unit: &Unit) {
    for b in set {
        if !refit.iter().any(|r| r.param == b.param) && unit.param(&b.param).is_ok() {
            refit.push(b.clone());
        }
    }
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
        let b = FreeBound::requested(unit, path, *range).map_err(bound_error)?;
        if !out.iter().any(|o| o.param == b.param) {
            out.push(FreeBound {
                polish_only: true,
                ..b
            });
        }
    }
    Ok(out)
}

pub(super) fn refit_error(path: &str, why: impl std::fmt::Display) -> DiagnoseError {
    DiagnoseError::Setup(format!("refit parameter {path}: {why}"))
}

/// A refit bound that does not resolve, as a setup error naming the parameter.
fn bound_error(e: BoundError) -> DiagnoseError {
    refit_error(&e.param, &e.problem)
}

/// Checks [`DiagnoseOptions::refit`]: every parameter exists in `unit` and its bounds are
/// finite and not upside down, empty or NaN ([`FreeBound::check`]).
pub(super) fn check_refit(unit: &Unit, refit: &[FreeBound]) -> Result<(), DiagnoseError> {
    for b in refit {
        unit.param(&b.param).map_err(|e| refit_error(&b.param, e))?;
        b.check().map_err(bound_error)?;
    }
    Ok(())
}
