//! `saturation`: the machine's magnetic saturation other than modelled, re-fitted as the
//! saturation curve's two points S(1.0), S(1.2) (with the field side).

use itaipu_dynamics::synthetic::EventKind;

use super::super::catalog::{
    declared, field_side, has_param, model_of, value, Cause, CauseError, CauseInfo, Context,
    Extension, Roles, Scenario,
};
use super::super::EventEvidence;

pub struct Saturation;

static INFO: CauseInfo = CauseInfo {
    id: "saturation",
    title: "magnetic saturation other than modelled",
    signature: "Q residual that grows with the flux (voltage) level and a Q bias after the event",
    extension: "machine saturation S(1.0), S(1.2) freed (with the AVR gain, T_E, X'_d and H)",
    key_params: &["machine.s10", "machine.s12"],
};

impl Cause for Saturation {
    fn info(&self) -> &'static CauseInfo {
        &INFO
    }

    fn acts(&self) -> super::super::catalog::Acts {
        super::super::catalog::Acts::Machine
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        let m = &roles.machine;
        let (s10, s12) = (format!("{m}.s10"), format!("{m}.s12"));
        if !has_param(&x.unit, &s10) || !has_param(&x.unit, &s12) {
            return Err(CauseError::not_applicable(format!(
                "machine {} has no S(1.0), S(1.2)",
                model_of(&x.unit, m)
            )));
        }
        let (a, b) = (value(&x.unit, &s10)?, value(&x.unit, &s12)?);
        x.extension_free = vec![declared(&x.unit, &s10, a)?, declared(&x.unit, &s12, b)?];
        // Saturation sets the incremental field-to-flux gain: a calibration with the wrong curve
        // bends the AVR and X'_d to make up for it; and a calibration that is off for any other
        // reason must not be "repaired" by a saturation curve (its baseline re-fits them too).
        x.interacting_free = field_side(&x.unit, roles.exciter.as_deref(), m);
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        super::q_window(ev)
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Scenario {
        Scenario {
            values: vec![
                ("machine.s10", 0.2 + 0.05 * spread(1)),
                ("machine.s12", 0.6 + 0.1 * spread(2)),
            ],
            key: None,
            kind: EventKind::FaultDip,
        }
    }
}
