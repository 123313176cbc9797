//! `exciter_limit`: the exciter's output limits reached in the dip, modelled by freeing the
//! exciter's ceiling E_MAX and floor E_MIN (with the AVR gain and the field side a calibration
//! without the limit bends). Two structures are tried and the better kept: a constant ceiling
//! (a rotating exciter, or a static one with its own supply) and, for SEXS, a ceiling fed from
//! the terminals, `E_fd,max = V_t·V_RMAX − K_C·X_adI_fd` (`SEXS_bus_fed`, `models.md` §12.3: a
//! thyristor bridge supplied by the generator's own voltage, whose ceiling falls with the dip).

use itaipu_dynamics::synthetic::EventKind;

use super::super::catalog::{
    fb, field_side, has_param, model_of, new_block, scanned, value, Cause, CauseError, CauseInfo,
    Context, Extension, Roles, Scenario, DEEP_SEARCH, LIMIT_DIP,
};
use super::super::trial::Tolerance;
use super::super::EventEvidence;

pub struct ExciterLimit;

static INFO: CauseInfo = CauseInfo {
    id: "exciter_limit",
    title: "exciter output limits reached",
    signature: "Q residual confined to the dip and the first recovery seconds (the field voltage \
                saturates on its ceiling or floor), small before and long after",
    extension: "exciter ceiling E_MAX and floor E_MIN freed (with the AVR gain); for SEXS also \
                a ceiling fed from the terminals, V_t·V_RMAX − K_C·X_adI_fd, the better kept",
    key_params: &["exciter.e_max", "exciter.e_min"],
};

impl Cause for ExciterLimit {
    fn info(&self) -> &'static CauseInfo {
        &INFO
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        let Some(exc) = roles.exciter.as_deref() else {
            return Err(CauseError::not_applicable("no exciter"));
        };
        let (pmax, pmin) = (format!("{exc}.e_max"), format!("{exc}.e_min"));
        if !has_param(&x.unit, &pmax) || !has_param(&x.unit, &pmin) {
            return Err(CauseError::not_applicable(format!(
                "exciter {} has no E_MAX/E_MIN limits",
                model_of(&x.unit, exc)
            )));
        }
        if ctx.deepest_dip.is_some_and(|d| d < LIMIT_DIP) {
            // A limit just above the operating point would only clamp E_fd to make up for a
            // mis-calibrated AVR gain.
            return Err(CauseError::not_applicable(format!(
                "no event dips |V| by {:.0} % or more, so the AVR is not driven to its limits",
                100.0 * LIMIT_DIP
            )));
        }
        let efd0 = ctx.efd0.ok_or_else(|| {
            CauseError::build("the field voltage at the operating point is unknown")
        })?;
        let (emax, emin) = (value(&x.unit, &pmax)?, value(&x.unit, &pmin)?);
        let hi = emax.max(efd0 + 3.0).max(2.0 * efd0);
        // The ceiling's range comes from the field voltage at the operating point (computed here).
        x.extension_free = vec![
            scanned(fb(&pmax, efd0 + 0.05, hi, emax.min(hi))?, 24),
            fb(&pmin, emin.min(-2.0), efd0 - 0.05, emin.min(efd0 - 0.05))?,
        ];
        // The AVR gain and time constant, X'_d and H: a calibration without the right limit
        // bends them to make up for it. T'_d0 stays as given: on the ceiling the field flux
        // rises at E_MAX/T'_d0, so P and Q cannot tell the two apart (see
        // `trial::NOMINAL_OFFSETS`). T_E is scanned with E_MAX: on and off the ceiling the two
        // trade along a curved valley (a faster exciter reaches the ceiling sooner, as a higher
        // ceiling would).
        x.interacting_free = field_side(&x.unit, Some(exc), &roles.machine);
        let te = format!("{exc}.te");
        for b in x.interacting_free.iter_mut().filter(|b| b.param == te) {
            b.scan = 8;
        }
        x.search_factor = DEEP_SEARCH;
        x.from_datasheet = true;
        Ok(())
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
        self.extend(x, roles, ctx)?;
        if variant == 0 {
            x.description =
                "exciter ceiling E_MAX and floor E_MIN freed (with the AVR gain)".into();
            return Ok(());
        }
        // The supply-fed ceiling: SEXS with the same gains, its limits per pu of V_t.
        // `extend` returned Ok: the unit has an exciter and E_fd0 is known.
        let (Some(exc), Some(efd0)) = (roles.exciter.as_deref(), ctx.efd0) else {
            return Err(CauseError::build("no exciter or no E_fd0"));
        };
        if model_of(&x.unit, exc) != "SEXS" {
            return Err(CauseError::not_applicable(
                "a supply-fed ceiling is built for SEXS only",
            ));
        }
        let i0 = ctx.xadifd0.filter(|i| *i > 0.0).ok_or_else(|| {
            CauseError::build("the field current at the operating point is unknown")
        })?;
        let get = |n: &str| value(&x.unit, &format!("{exc}.{n}"));
        let (emax, emin) = (get("e_max")?, get("e_min")?);
        let gains = [
            ("ta_tb", get("ta_tb")?),
            ("tb", get("tb")?),
            ("k", get("k")?),
            ("te", get("te")?),
            ("v_ref_offset", get("v_ref_offset")?),
        ];
        // At the operating point (V_t ≈ 1) the ceiling V_RMAX − K_C·I_fd0 must hold E_fd0: the
        // search starts K_C at 0.05 and spans the constant variant's ceilings plus the largest
        // commutation drop; a candidate whose ceiling is below E_fd0 does not initialise.
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

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        super::q_window(ev)
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Scenario {
        Scenario {
            values: vec![("exciter.e_max", 2.9 + 0.3 * spread(1))],
            key: Some(("exciter.e_max", Tolerance::Rel(0.05))),
            kind: EventKind::FaultDip,
        }
    }
}
