//! `terminal_load`: a load between the machine and the PMU's current measurement (auxiliaries,
//! a step-up transformer's magnetising branch), modelled by a constant-impedance P and Q load
//! at the terminal bus.

use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario,
};
use super::super::cause_kit::{add_block, declared, new_block};
use super::super::context::{Acts, Context};
use super::super::report::EventEvidence;
use super::signature;

pub struct TerminalLoad;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "terminal_load",
    title: "unmodelled load between the machine and the PMU",
    signature:
        "P and Q residuals proportional to the voltage deviation (largest in the dip), no lag",
    extension: "terminal_load block: a constant-impedance P and Q load at the terminal bus",
    key_params: &["load.p_load", "load.q_load"],
};

impl Cause for TerminalLoad {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Terminal
    }

    fn extend(&self, x: &mut Extension, _roles: &Roles, _ctx: &Context) -> Result<(), CauseError> {
        if x.unit.block("load").is_some() {
            return Err(NotApplicable::NameTaken {
                name: "load".into(),
            }
            .into());
        }
        add_block(&mut x.unit, "load", new_block("terminal_load", &[])?)?;
        x.extension_free = vec![
            declared(&x.unit, "load.p_load", 0.0)?,
            declared(&x.unit, "load.q_load", 0.0)?,
        ];
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::correlates_with(ev, "|V|", None)
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![
                ("load.p_load", 0.05 + 0.02 * spread(1)),
                ("load.q_load", 0.04 + 0.02 * spread(2)),
            ],
            key: None,
            kind: EventKind::FaultDip,
        })
    }
}
