//! `exciter_limit`: the exciter's output limits reached in the dip, modelled by freeing the
//! exciter's limits by their roles (with the AVR gain and the field side a calibration without
//! the limit bends), so that every exciter takes part: a constant ceiling and floor (the
//! `ceiling`/`floor` roles: SEXS's E_MAX/E_MIN; or, for an exciter whose E_fd limit is not a
//! parameter, the regulator's: IEEET1's V_RMAX/V_RMIN, ESST1A's V_AMAX/V_AMIN), and a ceiling
//! fed from the terminals, freed in place where the exciter is bus-fed (ST5B's V_RMAX and K_C)
//! or, for SEXS, by replacing it with
//! `E_fd,max = V_t·V_RMAX − K_C·X_adI_fd` (`SEXS_bus_fed`, `models.md` §12.3: a
//! thyristor bridge supplied by the generator's own voltage, whose ceiling falls with the dip).

use itaipu_dynamics::synthetic::EventKind;

use itaipu_dynamics::models::exciter::roles::ParamRole;
use itaipu_dynamics::registry::Role;
use itaipu_dynamics::unit::Unit;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario, Tolerance,
};
use super::super::cause_kit::{
    exciter_roles, fb, field_side, model_of, new_block, role_path, scanned, value, DEEP_SEARCH,
};
use super::super::context::{Acts, Context, LIMIT_DIP};
use super::super::report::EventEvidence;
use super::signature;

pub struct ExciterLimit;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "exciter_limit",
    title: "exciter output limits reached",
    signature: "Q residual confined to the dip and the first recovery seconds (the field voltage \
                saturates on its ceiling or floor), small before and long after",
    extension: "exciter ceiling E_MAX and floor E_MIN freed (with the AVR gain); for SEXS also \
                a ceiling fed from the terminals, V_t·V_RMAX − K_C·X_adI_fd, the better kept",
    key_params: &["exciter.e_max", "exciter.e_min"],
};

/// The structures of an exciter's limits a re-fit can free, in the order they are tried.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Structure {
    /// A constant E_fd ceiling and floor (the exciter's `ceiling`/`floor` roles).
    Constant,
    /// A constant ceiling and floor on the regulator's output upstream of the exciter stage
    /// (the `regulator_ceiling`/`regulator_floor` roles: IEEET1's V_R, ESST1A's V_A).
    Regulator,
    /// A bridge fed from the terminals, freed in place (the `supply_ceiling`, `commutation`,
    /// `supply_floor` roles: ST5B, SEXS_bus_fed).
    SupplyInPlace,
    /// SEXS replaced by `SEXS_bus_fed` with its gains (a constant-limit SEXS has no supply roles).
    SexsToBusFed,
}

/// The structures the exciter `exc` of `u` can take, with why the others cannot.
fn structures(u: &Unit, exc: &str) -> (Vec<Structure>, Vec<String>) {
    let r = exciter_roles(u, exc);
    let (mut s, mut why) = (vec![], vec![]);
    match (&r.ceiling, &r.floor) {
        (ParamRole::Param(_), ParamRole::Param(_)) => s.push(Structure::Constant),
        (c, f) => why.extend(c.reason().or(f.reason()).map(String::from)),
    }
    if s.is_empty() {
        match (&r.regulator_ceiling, &r.regulator_floor) {
            (ParamRole::Param(_), ParamRole::Param(_)) => s.push(Structure::Regulator),
            (c, f) => why.extend(c.reason().or(f.reason()).map(String::from)),
        }
    }
    if r.supply_ceiling.name().is_some() && r.commutation.name().is_some() {
        s.push(Structure::SupplyInPlace);
    } else if model_of(u, exc) == "SEXS" {
        s.push(Structure::SexsToBusFed);
    } else {
        why.extend(r.supply_ceiling.reason().map(String::from));
    }
    (s, why)
}

/// The field current X_adI_fd at the operating point [pu], which a ceiling fed from the
/// terminals is read against.
fn field_current(ctx: &Context) -> Result<f64, CauseError> {
    ctx.xadifd0
        .filter(|i| *i > 0.0)
        .ok_or_else(|| CauseError::build("the field current at the operating point is unknown"))
}

/// The path of the exciter `exc`'s parameter of `role` (`what` names it in the reason when the
/// exciter has none).
fn path(x: &Extension, exc: &str, role: &ParamRole, what: &str) -> Result<String, CauseError> {
    role_path(&x.unit, exc, role, what)
}

/// A constant E_fd ceiling and floor freed: the ceiling's range comes from the field voltage at
/// the operating point `efd0`.
fn constant(x: &mut Extension, exc: &str, efd0: f64) -> Result<(), CauseError> {
    let r = exciter_roles(&x.unit, exc);
    let (pmax, pmin) = (
        path(x, exc, &r.ceiling, "ceiling")?,
        path(x, exc, &r.floor, "floor")?,
    );
    let (emax, emin) = (value(&x.unit, &pmax)?, value(&x.unit, &pmin)?);
    let hi = emax.max(efd0 + 3.0).max(2.0 * efd0);
    x.extension_free = vec![
        scanned(fb(&pmax, efd0 + 0.05, hi, emax.min(hi))?, 24),
        fb(&pmin, emin.min(-2.0), efd0 - 0.05, emin.min(efd0 - 0.05))?,
    ];
    x.description = format!("exciter ceiling {pmax} and floor {pmin} freed (with the AVR gain)");
    Ok(())
}

/// The regulator's ceiling and floor freed. The regulator's output at the operating point is
/// the model's (E_fd0 through its exciter stage): the ceiling is searched from a tenth of its
/// value up, a candidate below the operating point does not initialise.
fn regulator(x: &mut Extension, exc: &str) -> Result<(), CauseError> {
    let r = exciter_roles(&x.unit, exc);
    let (pmax, pmin) = (
        path(x, exc, &r.regulator_ceiling, "regulator ceiling")?,
        path(x, exc, &r.regulator_floor, "regulator floor")?,
    );
    let (vmax, vmin) = (value(&x.unit, &pmax)?, value(&x.unit, &pmin)?);
    if !(vmax > 0.0) {
        return Err(NotApplicable::RegulatorCeiling {
            param: pmax,
            value: vmax,
        }
        .into());
    }
    x.extension_free = vec![
        scanned(fb(&pmax, 0.1 * vmax, 1.2 * vmax, vmax)?, 24),
        fb(&pmin, vmin.min(-vmax), vmin.max(-0.1 * vmax).min(0.0), vmin)?,
    ];
    x.description = format!("regulator ceiling {pmax} and floor {pmin} freed (with the AVR gain)");
    Ok(())
}

/// A bridge fed from the terminals freed in place: its supply ceiling (up to the constant
/// variant's ceilings plus the largest commutation drop at the field current `i0`), its
/// commutation factor and its floor.
fn supply_in_place(x: &mut Extension, exc: &str, efd0: f64, i0: f64) -> Result<(), CauseError> {
    let r = exciter_roles(&x.unit, exc);
    let (pmax, pkc, pmin) = (
        path(x, exc, &r.supply_ceiling, "supply ceiling")?,
        path(x, exc, &r.commutation, "commutation factor")?,
        path(x, exc, &r.supply_floor, "supply floor")?,
    );
    let (vmax, kc, vmin) = (
        value(&x.unit, &pmax)?,
        value(&x.unit, &pkc)?,
        value(&x.unit, &pmin)?,
    );
    let (lo, hi) = (efd0 + 0.05, vmax.max(efd0 + 3.0).max(2.0 * efd0) + 0.2 * i0);
    let floor_lo = vmin.min(-2.0);
    x.extension_free = vec![
        scanned(fb(&pmax, lo, hi, vmax.clamp(lo, hi))?, 24),
        fb(&pkc, 0.0, kc.max(0.2), kc.max(0.0))?,
        fb(
            &pmin,
            floor_lo,
            efd0 - 0.05,
            vmin.clamp(floor_lo, efd0 - 0.05),
        )?,
    ];
    x.description = format!(
        "exciter ceiling fed from the terminals ({pmax}, {pkc}) and floor {pmin} freed \
         (with the AVR gain)"
    );
    Ok(())
}

/// SEXS replaced by `SEXS_bus_fed` with its gains, its ceiling, commutation factor and floor
/// freed. At the operating point (V_t ≈ 1) the ceiling V_RMAX − K_C·I_fd0 must hold E_fd0: the
/// search starts K_C at 0.05 and spans the constant variant's ceilings plus the largest
/// commutation drop at the field current `i0`; a candidate whose ceiling is below E_fd0 does
/// not initialise.
fn sexs_to_bus_fed(x: &mut Extension, exc: &str, efd0: f64, i0: f64) -> Result<(), CauseError> {
    let get = |n: &str| value(&x.unit, &format!("{exc}.{n}"));
    let (emax, emin) = (get("e_max")?, get("e_min")?);
    let gains = [
        ("ta_tb", get("ta_tb")?),
        ("tb", get("tb")?),
        ("k", get("k")?),
        ("te", get("te")?),
        ("v_ref_offset", get("v_ref_offset")?),
    ];
    let k_c = 0.05;
    let (lo, hi) = (efd0 + 0.05, emax.max(efd0 + 3.0).max(2.0 * efd0) + 0.2 * i0);
    let vr_min = emin.min(-2.0);
    let mut values: Vec<(&str, f64)> = gains.to_vec();
    values.extend([
        ("vr_max", hi.min(emax + k_c * i0).max(lo + k_c * i0)),
        ("vr_min", vr_min),
        ("k_c", k_c),
    ]);
    let block = new_block("SEXS_bus_fed", &values)?;
    x.unit.put(exc, block, &[]).map_err(CauseError::build)?;
    x.extension_free = vec![
        scanned(fb(&format!("{exc}.vr_max"), lo, hi, emax + k_c * i0)?, 24),
        fb(&format!("{exc}.k_c"), 0.0, 0.2, k_c)?,
        fb(&format!("{exc}.vr_min"), vr_min, efd0 - 0.05, vr_min)?,
    ];
    x.description = "exciter ceiling fed from the terminals, V_t·V_RMAX − K_C·X_adI_fd, and \
                     floor V_t·V_RMIN freed (with the AVR gain)"
        .into();
    Ok(())
}

impl Cause for ExciterLimit {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Exciter
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        self.extend_variant(x, roles, ctx, 0)
    }

    fn variants(&self) -> usize {
        2
    }

    fn extend_variant(
        &self,
        x: &mut Extension,
        roles: &Roles,
        ctx: &Context,
        variant: usize,
    ) -> Result<(), CauseError> {
        let Some(exc) = roles.exciter.as_deref() else {
            return Err(NotApplicable::NoBlock {
                role: Role::Exciter,
                purpose: None,
            }
            .into());
        };
        let (list, why) = structures(&x.unit, exc);
        let Some(&structure) = list.get(variant) else {
            return Err(NotApplicable::Lacks {
                role: Role::Exciter,
                model: model_of(&x.unit, exc),
                lacks: "limits a re-fit can free".into(),
                why: (!why.is_empty()).then(|| why.join("; ")),
            }
            .into());
        };
        if !ctx.drives_avr_by(LIMIT_DIP) {
            // A limit just above the operating point would only clamp E_fd to make up for a
            // mis-calibrated AVR gain.
            return Err(NotApplicable::NoDip { dip: LIMIT_DIP }.into());
        }
        let efd0 = ctx.efd0.ok_or_else(|| {
            CauseError::build("the field voltage at the operating point is unknown")
        })?;
        match structure {
            Structure::Constant => constant(x, exc, efd0)?,
            Structure::Regulator => regulator(x, exc)?,
            Structure::SupplyInPlace => supply_in_place(x, exc, efd0, field_current(ctx)?)?,
            Structure::SexsToBusFed => sexs_to_bus_fed(x, exc, efd0, field_current(ctx)?)?,
        }
        // The AVR gain and time constant, X'_d and H: a calibration without the right limit
        // bends them to make up for it. T'_d0 stays as given: on the ceiling the field flux
        // rises at E_MAX/T'_d0, so P and Q cannot tell the two apart (see
        // `trial::NOMINAL_OFFSETS`). The field time constant is scanned with the ceiling: on and
        // off the ceiling the two trade along a curved valley (a faster exciter reaches the
        // ceiling sooner, as a higher ceiling would).
        x.interacting_free = field_side(&x.unit, Some(exc), &roles.machine);
        if let Some(te) = exciter_roles(&x.unit, exc).field_time_constant.name() {
            let te = format!("{exc}.{te}");
            for b in x.interacting_free.iter_mut().filter(|b| b.param == te) {
                b.scan = 8;
            }
        }
        x.search_factor = DEEP_SEARCH;
        x.from_datasheet = true;
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::q_window(ev)
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![("exciter.e_max", 2.9 + 0.3 * spread(1))],
            key: Some(("exciter.e_max", Tolerance::Rel(0.05))),
            kind: EventKind::FaultDip,
        })
    }
}
