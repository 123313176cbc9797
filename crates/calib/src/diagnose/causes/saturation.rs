//! `saturation`: the machine's magnetic saturation other than modelled, re-fitted as the
//! saturation curve's two points S(1.0), S(1.2) (with the field side).

use itaipu_dynamics::registry::Role;
use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario,
};
use super::super::cause_kit::{declared, field_side, has_param, model_of, value};
use super::super::context::{Acts, Context};
use super::super::report::EventEvidence;
use super::signature;

pub struct Saturation;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "saturation",
    title: "magnetic saturation other than modelled",
    signature: "Q residual that grows with the flux (voltage) level and a Q bias after the event",
    extension: "machine saturation S(1.0), S(1.2) freed (with the AVR gain, T_E, X'_d and H)",
    key_params: &["machine.s10", "machine.s12"],
};

impl Cause for Saturation {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Machine
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        let m = &roles.machine;
        let (s10, s12) = (format!("{m}.s10"), format!("{m}.s12"));
        if !has_param(&x.unit, &s10) || !has_param(&x.unit, &s12) {
            return Err(NotApplicable::Lacks {
                role: Role::Machine,
                model: model_of(&x.unit, m),
                lacks: "S(1.0), S(1.2)".into(),
                why: None,
            }
            .into());
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
        signature::q_window(ev)
    }

    /// A fitted curve that is no magnetisation curve
    /// ([`itaipu_dynamics::plausibility::is_magnetisation_curve`]): GENSAE's exponential
    /// S(1.0)·ψⁿ then has n ≤ 0, less saturation at higher flux. Such a curve can fit part of a
    /// record's misfit, but no machine has it, so it does not name saturation.
    fn unphysical(&self, fitted: &[(String, f64)], _ctx: &Context) -> Option<String> {
        let find = |suffix: &str| {
            fitted
                .iter()
                .find(|(p, _)| p.ends_with(suffix))
                .map(|(p, v)| (p.as_str(), *v))
        };
        let ((p10, s10), (p12, s12)) = (find(".s10")?, find(".s12")?);
        (!itaipu_dynamics::plausibility::is_magnetisation_curve(s10, s12)).then(|| {
            format!(
                "the fitted curve is no magnetisation curve ({p10} = {s10:.4}, {p12} = {s12:.4}: \
                 the saturation factor must grow with flux, S(1.2) > S(1.0))"
            )
        })
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![
                ("machine.s10", 0.2 + 0.05 * spread(1)),
                ("machine.s12", 0.6 + 0.1 * spread(2)),
            ],
            key: None,
            kind: EventKind::FaultDip,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::catalog::cause;

    fn ctx() -> Context {
        Context {
            rate_hz: 60.0,
            ..Default::default()
        }
    }

    /// The veto the candidates' scoring asks every cause (`Cause::vetoed`): a saturation
    /// curve that falls with flux is not named, one that grows is.
    #[test]
    fn a_saturation_curve_falling_with_flux_is_vetoed() {
        let sat = cause("saturation").unwrap();
        let fitted = |s10: f64, s12: f64| {
            vec![
                ("machine.s10".to_string(), s10),
                ("machine.s12".to_string(), s12),
                ("exciter.k".to_string(), 200.0),
            ]
        };
        let why = sat.vetoed(&fitted(0.398, 0.198), &ctx()).expect("vetoed");
        assert!(why.contains("no magnetisation curve"), "{why}");
        assert!(sat.vetoed(&fitted(0.3, 0.3), &ctx()).is_some());
        assert!(sat.vetoed(&fitted(0.12, 0.45), &ctx()).is_none());
        assert!(
            sat.vetoed(&fitted(0.0, 0.0), &ctx()).is_none(),
            "no saturation"
        );
        // Other causes are not judged by it.
        let skew = cause("measurement_skew").unwrap();
        assert!(skew
            .vetoed(&[("measurement.pq_delay_s".to_string(), 0.025)], &ctx())
            .is_none());
    }
}
