//! `oel`: an over-excitation limiter acting after the event, modelled by an inverse-time OEL on
//! the field current at the exciter's summing point (with the field side).

use itaipu_dynamics::registry::Role;
use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario, Tolerance,
};
use super::super::cause_kit::{
    add_block, declared, declared_range, fb, field_side, model_of, new_block, scanned, DEEP_SEARCH,
};
use super::super::context::{Acts, Context, LIMIT_DIP, OEL_IFD_RISE};
use super::super::report::EventEvidence;
use super::signature;

pub struct Oel;

static INFO: CauseInfo<'static> = CauseInfo {
    id: "oel",
    title: "over-excitation limiter acting after the event",
    signature:
        "Q residual that appears seconds after the event, while the field current stays high, \
                and grows (the limiter pulls the field back)",
    extension:
        "inverse-time OEL on the field current (rated current, picking up at 105 % and pulling back \
                to 100 % of it; I²t capacity, integral gain), with the AVR gain, T_E, X'_d and H",
    key_params: &["oel.ifd_rated", "oel.a_max"],
};

impl Cause for Oel {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::Exciter
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        let Some(exc) = roles.exciter.as_deref() else {
            return Err(NotApplicable::NoBlock {
                role: Role::Exciter,
                purpose: Some("for an OEL to act on"),
            }
            .into());
        };
        let has_voel = x
            .unit
            .block(exc)
            .is_some_and(|b| b.ports().iter().any(|p| p.name == "voel"));
        if !has_voel {
            return Err(NotApplicable::Lacks {
                role: Role::Exciter,
                model: model_of(&x.unit, exc),
                lacks: "OEL input".into(),
                why: None,
            }
            .into());
        }
        if x.unit.block("oel").is_some() {
            return Err(NotApplicable::NameTaken { name: "oel".into() }.into());
        }
        if !ctx.drives_avr_by(LIMIT_DIP) && ctx.field_current_rise.is_none_or(|r| r < OEL_IFD_RISE)
        {
            // Without a dip or a sustained field forcing the field current is not driven into
            // overload; a limiter picking up just above the operating point would only trim a
            // mis-calibrated AVR gain.
            return Err(NotApplicable::NoFieldForcing {
                dip: LIMIT_DIP,
                rise: OEL_IFD_RISE,
            }
            .into());
        }
        let i0 = ctx.xadifd0.ok_or_else(|| {
            CauseError::build("the field current at the operating point is unknown")
        })?;
        if !(i0 > 0.0) {
            return Err(NotApplicable::NotPositiveAtOperatingPoint {
                quantity: "field current",
            }
            .into());
        }
        // The limiter's settings are read the usual way: it picks up at 105 % of the rated field
        // current and regulates back to 100 % (the block's declared defaults, left as they are:
        // the common setting of an inverse-time OEL). What a record identifies is the level the
        // limiter regulates the field current to, so the rated current is what is searched, not
        // the pickup (a pickup tied to the regulated level would be fitted at the regulated level,
        // 5 % low). The rated current's range is computed here, not declared: it is read against the calibrated unit's pre-event field current i0, and the re-fit
        // from the datasheet values (below) may put the unit's own pre-event current well under
        // i0 (a calibration that mimicked the limiter raised X_d), so the range reaches down to
        // 0.6 × i0; a candidate whose own current starts above its pickup does not initialise.
        let oel = new_block(
            "oel",
            &[
                ("ifd_rated", i0),
                ("a_max", 2.0),
                ("k_cool", 0.05),
                ("k_i", 0.01),
                ("voel_min", -0.5),
            ],
        )?;
        add_block(&mut x.unit, "oel", oel)?;
        // Rated current and I²t capacity scanned jointly: together they set when the limiter
        // acts (a lower pickup with a larger capacity acts as late), and off that valley the
        // objective is flat (the limiter never acts) or far worse (it acts at the wrong time).
        x.extension_free = vec![
            scanned(fb("oel.ifd_rated", 0.6 * i0, 1.6 * i0, i0)?, 12),
            scanned(declared(&x.unit, "oel.a_max", 0.3)?, 8),
            declared(&x.unit, "oel.k_i", 0.03)?,
        ];
        // A calibration without the limiter bends the AVR and the field dynamics to make up for
        // the field being pulled back (as for `exciter_limit`).
        x.interacting_free = field_side(&x.unit, Some(exc), &roles.machine);
        x.search_factor = DEEP_SEARCH;
        x.from_datasheet = true;
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], _ctx: &Context) -> Vec<String> {
        signature::q_window(ev)
    }

    /// An inverse-time limiter whose I²t capacity A_max ends at the bottom of its declared
    /// range (within 0.1 % of the range's width on its search scale, as for any bound:
    /// [`crate::problem::FreeParam::at_bound`]) acts the moment the field current passes its
    /// pickup: the residual asks for a limit without the thermal delay that makes an OEL act
    /// seconds after the event, which the cause does not explain (an instantaneous field-current
    /// limit, a compensator or a bent AVR does; the upper-end rule of the candidates, turned to
    /// the end where this parameter gives the most effect): a reactive-current droop outside the
    /// catalog, fitted as an OEL, ends there.
    fn unphysical(&self, fitted: &[(String, f64)], _ctx: &Context) -> Option<String> {
        let a = fitted.iter().find(|(p, _)| p == "oel.a_max")?.1;
        let (lo, hi) = declared_range("oel", "a_max")?;
        (crate::problem::box_coordinate(a, lo, hi) < 1e-3).then(|| {
            format!(
                "its I²t capacity ends at the bottom of its range (oel.a_max = {a:.3} in [{lo}, {hi}] pu²s): \
                 the limiter would act the moment the field current passes its pickup, without the thermal \
                 delay of an inverse-time OEL, so the residual asks for another effect"
            )
        })
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            // The truth reads its settings against the pre-event field current (the search's
            // start) and picks up at 104-106 % of it; the key is the regulated current.
            values: vec![
                ("oel.i_pickup", 1.05 + 0.01 * spread(1)),
                ("oel.a_max", 0.1 + 0.05 * spread(2)),
                ("oel.k_i", 0.05),
            ],
            key: Some(("oel.ifd_rated", Tolerance::Rel(0.05))),
            kind: EventKind::FaultDip,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::catalog::cause;

    /// The veto every candidate's scoring asks (`Cause::vetoed`): an OEL whose I²t capacity
    /// ends at the bottom of the block's declared range (0.02 pu²s, searched on a log scale up
    /// to 30) is not named; typical capacities (0.06-1.5 pu²s) are, and so is one just off the
    /// bottom.
    #[test]
    fn an_oel_without_thermal_capacity_is_not_named() {
        let oel = cause("oel").unwrap();
        let fitted = |a_max: f64| {
            vec![
                ("oel.ifd_rated".to_string(), 1.7),
                ("oel.a_max".to_string(), a_max),
                ("oel.k_i".to_string(), 0.01),
            ]
        };
        let ctx = Context::default();
        assert_eq!(declared_range("oel", "a_max"), Some((0.02, 30.0)));
        let why = oel.vetoed(&fitted(0.02), &ctx).expect("vetoed");
        assert!(
            why.contains("oel.a_max = 0.020") && why.contains("thermal"),
            "{why}"
        );
        // Within 0.1 % of the log range (a factor 30/0.02 = 1500: 0.02 × 1500^0.001 = 0.02015).
        assert!(oel.vetoed(&fitted(0.02014), &ctx).is_some());
        for a in [0.0202, 0.061, 0.27, 1.53, 30.0] {
            assert!(oel.vetoed(&fitted(a), &ctx).is_none(), "A_max = {a}");
        }
        // Without the capacity among the fitted values there is nothing to judge.
        assert!(oel.vetoed(&fitted(0.02)[..1], &ctx).is_none());
    }
}
