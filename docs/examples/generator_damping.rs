// crates/calib/src/diagnose/causes/generator_damping.rs
//! `generator_damping`: mechanical damping other than the model's (the damper windings'
//! asynchronous torque and the turbine's own damping, which the machine's D stands for).

use itaipu_dynamics::synthetic::EventKind;

use crate::diagnose::catalog::{
    declared, value, Acts, Cause, CauseError, CauseInfo, Context, Extension, NotApplicable, Roles,
    Scenario,
};

pub struct GeneratorDamping;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "generator_damping",
    title: "mechanical damping other than modelled",
    signature: "electromechanical swing in the P residual decaying at the wrong rate",
    extension: "the machine's damping D freed",
    key_params: &["machine.d"],
};

impl Cause for GeneratorDamping {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    /// The damping acts through the swing equation: a playback mode that imposes P cannot
    /// show it.
    fn acts(&self) -> Acts {
        Acts::Mechanical
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        let d = format!("{}.d", roles.machine);
        let v = value(&x.unit, &d).map_err(|_| NotApplicable::NoParam {
            param: d.clone(),
            in_tie: false,
        })?;
        x.extension_free = vec![declared(&x.unit, &d, v)?];
        Ok(())
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![("machine.d", 1.0 + 0.5 * spread(1))],
            key: None,
            kind: EventKind::FaultDip,
        })
    }
}
