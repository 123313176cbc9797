//! What a cause's file builds its extension with: blocks from the library, parameters freed
//! within their declared ranges or within ranges computed from the operating point, the
//! exciter's parameters by their roles, and the field-side parameters a calibration bends.

use itaipu_dynamics::block::Block;
use itaipu_dynamics::models::exciter::roles::{ExciterRoles, ParamRole};
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

use super::cause::{CauseError, NotApplicable};

/// Swarm-length factor of a candidate whose regime the events reach and that re-frees a
/// calibration's bent stage parameters (limits, governor, PSS).
pub const DEEP_SEARCH: usize = 5;

pub(crate) fn model_of(unit: &Unit, name: &str) -> String {
    unit.block(name)
        .map(|b| b.model().to_string())
        .unwrap_or_default()
}

pub(crate) fn new_block(model: &str, values: &[(&str, f64)]) -> Result<Box<dyn Block>, CauseError> {
    let info = registry::find(model)
        .ok_or_else(|| CauseError::build(format!("model {model} is not in the registry")))?;
    let mut b = info.create();
    for (name, v) in values {
        let ps = b.params_mut();
        let k = ps
            .index_of(name)
            .ok_or_else(|| CauseError::build(format!("{model} has no parameter {name}")))?;
        ps.set(k, *v);
    }
    Ok(b)
}

pub(crate) fn value(unit: &Unit, path: &str) -> Result<f64, CauseError> {
    unit.param(path)
        .map(|r| unit.get(r))
        .map_err(CauseError::build)
}

pub(crate) fn has_param(unit: &Unit, path: &str) -> bool {
    unit.param(path).is_ok()
}

/// `path` of `unit` (the extended unit) free within its declared range
/// ([`itaipu_dynamics::params::ParamSpec::range`], the plausible range), starting at `start`
/// (clamped): a cause's search range comes from the parameter's declaration. Only ranges that
/// depend on the operating point, the evidence or the PMU rate are computed in a cause's file
/// (with [`fb`]).
pub(crate) fn declared(unit: &Unit, path: &str, start: f64) -> Result<FreeBound, CauseError> {
    FreeBound::declared(unit, path)
        .map(|b| b.starting_at(start))
        .map_err(CauseError::build)
}

/// The declared range (`ParamSpec::range`) of parameter `param` of library model `model`: what
/// [`declared`] frees it within, for a rule that reads a fitted value against it.
pub(crate) fn declared_range(model: &str, param: &str) -> Option<(f64, f64)> {
    let block = itaipu_dynamics::registry::find(model)?.create();
    let p = block.params();
    let i = p.index_of(param)?;
    Some(p.specs()[i].range)
}

/// `param` free within `[min, max]` computed by the cause (from the operating point, the
/// evidence or the PMU rate), starting at `start` (clamped). A range that is empty, upside down
/// or not finite (an operating point that leaves the search no room, a NaN from a unit that
/// does not initialise) is never built: the cause is not applicable, and the note says why.
pub(crate) fn fb(param: &str, min: f64, max: f64, start: f64) -> Result<FreeBound, CauseError> {
    let b = FreeBound::new(param, min, max);
    b.check().map_err(|e| NotApplicable::NoRoom {
        param: param.to_string(),
        problem: e.problem.to_string(),
    })?;
    Ok(b.starting_at(start))
}

pub(crate) fn scanned(b: FreeBound, points: usize) -> FreeBound {
    b.scanned(points)
}

/// Adds block `name` (the wiring is resolved once all edits are made).
pub(crate) fn add_block(
    unit: &mut Unit,
    name: &str,
    block: Box<dyn Block>,
) -> Result<(), CauseError> {
    unit.add(name, block, &[]).map_err(CauseError::build)
}

/// Rewires ports of the existing instance `name`, keeping its other connections.
pub(crate) fn rewire(
    unit: &mut Unit,
    name: &str,
    ports: &[(&str, &str)],
) -> Result<(), CauseError> {
    let rw: Vec<(String, String)> = ports
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    unit.rewire(name, &rw).map_err(CauseError::build)
}

/// Frees the positive parameter `path` of `u` within `[v/factor, v·factor]` around its value
/// `v`, clipped to the model's declared range (a calibrated value may sit on the bound of the
/// calibration that bent it, so the band is wide). `None` if it does not exist, is not > 0, or
/// leaves no band (an infinite value, a factor of 1 or less): it is then not freed.
pub(crate) fn around(u: &Unit, path: &str, factor: f64) -> Option<FreeBound> {
    let (_, spec, v) = u.params().into_iter().find(|(p, _, _)| p == path)?;
    if !(v > 0.0) {
        return None;
    }
    let lo = (v / factor).max(spec.range.0).min(v);
    let hi = (v * factor).min(spec.range.1).max(v);
    fb(path, lo, hi, v).ok()
}

/// The roles the exciter block `exc` of `u` declares ([`ExciterRoles`]: its model's, or a
/// user diagram's `[exciter_roles]` table): the parameters a cause reasons about by role
/// (gain, field time constant, ceiling, ...), never by one model's names. A block that declares
/// none makes every role not applicable, with the reason.
pub fn exciter_roles(u: &Unit, exc: &str) -> ExciterRoles {
    match u.block(exc) {
        Some(b) => b.exciter_roles().unwrap_or_else(|| {
            ExciterRoles::none(&format!(
                "the exciter model {} declares no exciter roles",
                b.model()
            ))
        }),
        None => ExciterRoles::none("the unit has no exciter"),
    }
}

/// `{exc}.{parameter}` of `role`, or the role's reason as a "not applicable" error (`what`
/// names the role in it, e.g. "a ceiling").
pub(crate) fn role_path(
    u: &Unit,
    exc: &str,
    role: &ParamRole,
    what: &str,
) -> Result<String, CauseError> {
    match role {
        ParamRole::Param(p) => Ok(format!("{exc}.{p}")),
        ParamRole::NotApplicable(why) => Err(NotApplicable::Lacks {
            role: Role::Exciter,
            model: model_of(u, exc),
            lacks: what.to_string(),
            why: Some(why.to_string()),
        }
        .into()),
    }
}

/// The exciter's gain and field time constant by role, each freed within `factor` of its value
/// ([`around`]) where the exciter has it: what a calibration without a field-side cause bends.
pub(crate) fn exciter_gain_and_time_constant(u: &Unit, exc: &str, factor: f64) -> Vec<FreeBound> {
    let r = exciter_roles(u, exc);
    [&r.gain, &r.field_time_constant]
        .into_iter()
        .filter_map(|role| role.name().map(|p| format!("{exc}.{p}")))
        .filter_map(|p| around(u, &p, factor))
        .collect()
}

/// The calibrated parameters a calibration without a field-side cause (an exciter limit, an
/// OEL, a saturation curve) bends to make up for it: the exciter's gain and field time constant
/// (by role: SEXS's K and T_E, ST5B's K_R and T_1, ...) within ×3 (a bent value may sit on its
/// calibration's bound), X'_d and H within ×1.6. T'_d0 stays as given (see
/// `trial::NOMINAL_OFFSETS`).
pub(crate) fn field_side(u: &Unit, exciter: Option<&str>, machine: &str) -> Vec<FreeBound> {
    let avr = exciter
        .into_iter()
        .flat_map(|x| exciter_gain_and_time_constant(u, x, 3.0));
    avr.chain(
        [
            around(u, &format!("{machine}.x_d_prime"), 1.6),
            around(u, &format!("{machine}.h"), 1.6),
        ]
        .into_iter()
        .flatten(),
    )
    .collect()
}
