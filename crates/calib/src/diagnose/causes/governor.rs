//! `governor`: governor action missing or mis-modelled, re-fitted as a HYGOV (added when the
//! unit has another governor) with a speed deadband and its gate-rate limit.

use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario,
};
use super::super::cause_kit::{
    add_block, around, declared, exciter_roles, model_of, new_block, rewire, scanned, value,
    DEEP_SEARCH,
};
use super::super::context::{Acts, Context, GOVERNOR_DF_HZ};
use super::super::report::EventEvidence;
use super::signature;

pub struct Governor;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "governor",
    title: "governor action missing or mis-modelled",
    signature:
        "slow P residual that follows the frequency deviation (seconds), growing through the \
                record",
    extension: "HYGOV (added, or refitted) with a speed deadband and its gate rate limit VELM free",
    key_params: &["deadband.db", "governor.velm"],
};

impl Cause for Governor {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Mechanical
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        let Some(g) = roles.governor.as_deref() else {
            return Err(NotApplicable::NoBlock {
                role: Role::Governor,
                purpose: None,
            }
            .into());
        };
        if x.unit.block("deadband").is_some() {
            return Err(NotApplicable::NameTaken {
                name: "deadband".into(),
            }
            .into());
        }
        let model = model_of(&x.unit, g);
        let hygov = model.eq_ignore_ascii_case("HYGOV");
        if !hygov {
            // Governor action missing: put a typical HYGOV in its place.
            let block = registry::find("HYGOV")
                .ok_or_else(|| CauseError::build("HYGOV is not in the registry"))?
                .create();
            x.unit.put(g, block, &[]).map_err(CauseError::build)?;
            x.description = format!(
                "HYGOV (typical values) in place of {model}, with a speed deadband; {}",
                INFO.extension
            );
        }
        add_block(
            &mut x.unit,
            "deadband",
            new_block("speed_deadband", &[("db", 0.0)])?,
        )?;
        rewire(&mut x.unit, g, &[("speed", "speed_db")])?;
        let velm = value(&x.unit, &format!("{g}.velm"))?;
        x.extension_free = vec![
            scanned(declared(&x.unit, "deadband.db", 0.0)?, 9),
            scanned(declared(&x.unit, &format!("{g}.velm"), velm)?, 4),
        ];
        let (r, tw) = (
            value(&x.unit, &format!("{g}.r_perm"))?,
            value(&x.unit, &format!("{g}.t_w"))?,
        );
        // On a frequency excursion the machine's inertia carries the power the governor does
        // not: a calibration without the governor's nonlinearity bends H to make up for it.
        // The permanent droop is scanned with the deadband: both cut the steady response to a
        // frequency deviation, so a calibration without the deadband raises the droop instead.
        x.interacting_free = vec![
            scanned(declared(&x.unit, &format!("{g}.r_perm"), r)?, 4),
            declared(&x.unit, &format!("{g}.t_w"), tw)?,
        ];
        let m = &roles.machine;
        x.interacting_free
            .extend(around(&x.unit, &format!("{m}.h"), 1.6));
        x.interacting_free
            .extend(around(&x.unit, &format!("{m}.x_d_prime"), 1.6));
        if let Some(exc) = &roles.exciter {
            let gain = exciter_roles(&x.unit, exc).gain;
            if let Some(k) = gain.name() {
                x.interacting_free
                    .extend(around(&x.unit, &format!("{exc}.{k}"), 3.0));
            }
        }
        if ctx.sustained_df_hz.is_none_or(|df| df > GOVERNOR_DF_HZ) {
            x.search_factor = DEEP_SEARCH;
        }
        if !hygov {
            // A new governor: every parameter the fit needs is new, count them all.
            x.extension_free.append(&mut x.interacting_free);
        }
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::correlates_with(ev, "frequency", Some("P"))
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![
                ("deadband.db", 0.002 + 0.0005 * spread(1)),
                ("governor.velm", 0.01),
            ],
            key: None,
            kind: EventKind::FrequencyExcursion,
        })
    }
}
