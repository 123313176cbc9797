//! `pss_state`: the PSS in service other than modelled: taken out when the model has one, a
//! typical STAB3 put in when it has none.

use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario,
};
use super::super::cause_kit::{
    add_block, around, declared, exciter_gain_and_time_constant, fb, model_of, value, DEEP_SEARCH,
};
use super::super::context::{Acts, Context};
use super::super::report::EventEvidence;
use super::signature;

pub struct PssState;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "pss_state",
    title: "PSS in service other than modelled",
    signature: "electromechanical swing in the P residual with the wrong damping after the event",
    extension: "the PSS removed when the model has one; a STAB3 added when it has none",
    key_params: &["pss.in_service"],
};

impl Cause for PssState {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Exciter
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        let Some(exc) = roles.exciter.as_deref() else {
            return Err(NotApplicable::NoBlock {
                role: Role::Exciter,
                purpose: Some("for a PSS to act on"),
            }
            .into());
        };
        if let Some(p) = &roles.pss {
            let model = model_of(&x.unit, p);
            x.unit = x.unit.without(&[p.as_str()]).map_err(CauseError::build)?;
            x.description = format!("the PSS ({model}) taken out of service");
            x.discrete_params = 1;
            x.fixed = vec![("pss.in_service".into(), 0.0)];
        } else {
            let stab3 = registry::find("STAB3")
                .ok_or_else(|| CauseError::build("STAB3 is not in the registry"))?
                .create();
            add_block(&mut x.unit, "pss", stab3)?;
            x.description = "a STAB3 PSS (typical values) put in service".into();
            x.extension_free = vec![
                declared(&x.unit, "pss.k_x", 1.0)?,
                declared(&x.unit, "pss.t_x2", 3.0)?,
            ];
            x.discrete_params = 1;
            x.fixed = vec![("pss.in_service".into(), 1.0)];
        }
        // A calibration with the PSS as modelled tuned the AVR, the inertia and the field
        // dynamics to make up for it: they move with the PSS's state (a longer search).
        x.search_factor = DEEP_SEARCH;
        let m = &roles.machine;
        x.interacting_free
            .extend(exciter_gain_and_time_constant(&x.unit, exc, 3.0));
        for (p, factor) in [
            (format!("{m}.h"), 1.6),
            (format!("{m}.x_d_prime"), 2.5),
            (format!("{m}.t_d0_prime"), 1.6),
        ] {
            x.interacting_free.extend(around(&x.unit, &p, factor));
        }
        let d = format!("{m}.d");
        if let Ok(v) = value(&x.unit, &d) {
            // Computed from the unit's value: up to 3 pu more damping than it has.
            x.interacting_free.push(fb(&d, 0.0, v.max(0.0) + 3.0, v)?);
        }
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::dominant_p_mode(ev)
    }

    fn scenario(&self, _spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![],
            key: None,
            kind: EventKind::FaultDip,
        })
    }
}
