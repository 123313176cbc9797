//! The catalog of causes: the registry [`CAUSES`] of the built-in causes (one file per cause in
//! `causes/`, each implementing [`Cause`]), their lookup by id, and what every cause shares,
//! re-exported from the files that define it ([`super::cause`], [`super::context`],
//! [`super::cause_kit`]).
//!
//! One definition serves two uses: [`extend`] builds the extended unit that `diagnose` re-fits,
//! and [`hide`] builds the same extension with chosen values, so that `synth` can hide a cause
//! in the truth of a synthetic event.

use std::collections::BTreeMap;

use itaipu_dynamics::unit::Unit;

use super::cause::hidden_unit;
pub use super::cause::{
    extend_cause, extend_every_variant, hideable_params, instance_with_role, nuisance, Acts, Cause,
    CauseError, CauseInfo, Context, Extension, HideError, NotApplicable, Roles, Scenario,
    Tolerance, NUISANCE,
};
/// The helpers a cause file uses, for the documentation's example cause compiled in the tests.
#[cfg(test)]
pub(crate) use super::cause_kit::{declared, value};
pub use super::cause_kit::{exciter_roles, DEEP_SEARCH};
pub use super::causes::CAUSES;
pub use super::context::{
    resonance_stands_out, GOVERNOR_DF_HZ, LIMIT_DIP, OEL_IFD_RISE, RESONANCE_P,
    RESONANCE_PROMINENCE,
};

/// The cause with id `id`.
pub fn cause(id: &str) -> Option<&'static dyn Cause> {
    CAUSES.iter().copied().find(|c| c.info().id == id)
}

/// Looks a cause up by id.
pub fn find(id: &str) -> Option<CauseInfo<'static>> {
    cause(id).map(|c| c.info())
}

/// Ids of all causes, for messages.
pub fn ids() -> String {
    CAUSES
        .iter()
        .map(|c| c.info().id)
        .collect::<Vec<_>>()
        .join(", ")
}

/// An unknown id's message lists the registry's ids, so it is written here, beside them.
impl std::fmt::Display for CauseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CauseError::Unknown(id) => write!(f, "unknown cause '{id}' (known: {})", ids()),
            CauseError::NotApplicable(why) => write!(f, "{why}"),
            CauseError::Build(msg) => f.write_str(msg),
        }
    }
}

/// The built-in cause `id`, or [`CauseError::Unknown`].
fn known(id: &str) -> Result<&'static dyn Cause, CauseError> {
    cause(id).ok_or_else(|| CauseError::Unknown(id.to_string()))
}

/// Builds the extension of `unit` for cause `cause_id` ([`Cause::extend`]), with the set-point
/// offsets (nuisance parameters) freed in every re-fit.
pub fn extend(cause_id: &str, unit: &Unit, ctx: &Context) -> Result<Extension, CauseError> {
    extend_variant(cause_id, unit, ctx, 0)
}

/// The extensions of every variant of a cause ([`Cause::variants`]): variant 0's error is the
/// cause's; a later variant that cannot be built is left out.
pub fn extend_all(
    cause_id: &str,
    unit: &Unit,
    ctx: &Context,
) -> Result<Vec<Extension>, CauseError> {
    extend_every_variant(known(cause_id)?, unit, ctx)
}

/// The extension of variant `variant` of a cause.
pub fn extend_variant(
    cause_id: &str,
    unit: &Unit,
    ctx: &Context,
    variant: usize,
) -> Result<Extension, CauseError> {
    extend_cause(known(cause_id)?, unit, ctx, variant)
}

/// The unit with `cause` hidden in it: the extension of [`extend`] with `values` set
/// (`block.param` paths among [`hideable_params`], e.g. `shaft.f_torsion_hz`), ties applied.
/// Returns the extension too (what was added, for reports).
pub fn hide(
    cause: &str,
    unit: &Unit,
    ctx: &Context,
    values: &BTreeMap<String, f64>,
) -> Result<(Unit, Extension), HideError> {
    let ext = extend(cause, unit, ctx).map_err(|e| HideError::from_cause(cause, unit, e))?;
    let known = hideable_params(unit, &ext);
    for path in values.keys() {
        if let Some((from, _)) = ext.ties.iter().find(|(_, to)| to == path) {
            return Err(HideError::Request(format!(
                "{cause}: {path} follows {from}; set {from} instead"
            )));
        }
        if !known.contains(path) {
            return Err(HideError::Request(format!(
                "{cause}: unknown parameter '{path}' (its parameters: {})",
                known.join(", ")
            )));
        }
    }
    let u = hidden_unit(&ext, values.iter().map(|(p, v)| (p.as_str(), *v)))?;
    Ok((u, ext))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::trial::base_unit;

    fn ctx(efd0: f64, rate_hz: f64) -> Context {
        Context {
            efd0: Some(efd0),
            xadifd0: Some(2.0),
            rate_hz,
            ..Default::default()
        }
    }

    fn not_applicable(cause: &str, c: &Context) -> String {
        match extend(cause, &base_unit(), c) {
            Err(CauseError::NotApplicable(why)) => why.to_string(),
            Err(e) => panic!("{cause}: {e:?}"),
            Ok(x) => panic!(
                "{cause}: built with {:?}",
                x.free()
                    .map(|b| (&b.param, b.min, b.max))
                    .collect::<Vec<_>>()
            ),
        }
    }

    /// A range a cause computes from the operating point that leaves no room (an
    /// E_fd0 below the floor's range, a NaN E_fd0 from a unit that does not initialise, a PMU
    /// rate whose Nyquist frequency is below the shaft band) is never built as a bound with
    /// min >= max (`f64::clamp` panicked on some): the cause is not applicable, naming the
    /// parameter. An ordinary operating point builds proper bounds.
    #[test]
    fn a_range_with_no_room_makes_the_cause_not_applicable() {
        let why = not_applicable("exciter_limit", &ctx(f64::NAN, 60.0));
        assert!(why.contains("exciter.e_max"), "{why}");
        let why = not_applicable("exciter_limit", &ctx(-3.0, 60.0));
        assert!(why.contains("exciter.e_min"), "{why}");
        let why = not_applicable("torsional_mode", &ctx(2.0, 4.0));
        assert!(why.contains("shaft.f_torsion_hz"), "{why}");
        for cause in ["exciter_limit", "torsional_mode", "measurement_skew", "oel"] {
            for v in 0..extend_all(cause, &base_unit(), &ctx(2.0, 60.0))
                .unwrap()
                .len()
            {
                let x = extend_variant(cause, &base_unit(), &ctx(2.0, 60.0), v).unwrap();
                for b in x.free() {
                    assert!(b.check().is_ok(), "{cause} ({v}): {b:?}");
                }
            }
        }
    }
}
