//! `torsional_mode`: a torsional mode of the turbine-generator shaft, modelled by splitting the
//! calibrated rigid inertia into a two-mass shaft (turbine and generator masses joined by a
//! spring of the mode's frequency).

use itaipu_dynamics::registry::Role;
use itaipu_dynamics::synthetic::EventKind;

use super::super::cause::{
    Cause, CauseError, CauseInfo, Extension, NotApplicable, Roles, Scenario, Tolerance,
};
use super::super::cause_kit::{add_block, declared, fb, new_block, rewire, scanned, value};
use super::super::context::{Acts, Context};
use super::super::report::EventEvidence;
use super::signature;
use crate::evidence::PEAK_WINDOW_HZ;

pub struct TorsionalMode;

/// Upper edge of the electromechanical band [Hz] (`models.md` §12.1: hydro torsional modes lie
/// well above the 0.2-2 Hz electromechanical band): the lowest torsional frequency searched. Below
/// it a heavily damped "shaft" only filters the mechanical power the governor delivers, which is
/// the governor's and the swing's business: a search that reaches into the band can dress a
/// governor's nonlinearity (a deadband) as a heavily damped mode near 2 Hz.
pub const ELECTROMECHANICAL_BAND_MAX_HZ: f64 = 2.0;

/// Largest damping ratio of a torsional mode of a turbine-generator shaft: a bare shaft's mode
/// has 0.001-0.01 (the `two_mass_shaft` block's declared typical, `models.md` §12.1) and the
/// turbine's water and the generator's damper windings add a few per cent at most, so 0.1 is an
/// order of magnitude above the first and twice the second; at 0.1 the mode still rings
/// (its amplitude falls by e^{−2πζ} ≈ 0.53 a cycle), above it the fitted "mode" is a filter on
/// the mechanical power, which other effects (a governor's nonlinearity, a reactive droop) can
/// fit as well.
pub const SHAFT_ZETA_MAX: f64 = 0.1;

/// The band a torsional mode is searched in [Hz]: from the electromechanical band's upper edge to
/// 90 % of the Nyquist frequency (where the PMU's anti-aliasing filter starts to eat the mode),
/// at most 25 Hz.
fn torsional_band(ctx: &Context) -> (f64, f64) {
    let f_lo = ELECTROMECHANICAL_BAND_MAX_HZ;
    (f_lo, (0.45 * ctx.rate_hz).clamp(f_lo, 25.0))
}

static INFO: CauseInfo<'static> = CauseInfo {
    id: "torsional_mode",
    title: "torsional mode of the turbine-generator shaft",
    signature: "a lightly damped oscillation in the P residual above the electromechanical modes, \
                present after every disturbance",
    extension:
        "two_mass_shaft between the governor and the machine (H_t, mode frequency, damping ratio), \
                machine.h becomes the generator mass",
    key_params: &["shaft.f_torsion_hz", "shaft.zeta"],
};

impl Cause for TorsionalMode {
    fn info(&self) -> CauseInfo<'_> {
        INFO
    }

    fn acts(&self) -> Acts {
        Acts::ActivePower
    }

    /// The shaft's mode is searched up to the top of [`torsional_band`]; in playback it is
    /// driven by the recorded voltage's content at the mode (the unit's own oscillation seen
    /// through the grid), which a low-passed input removes.
    fn band_top_hz(&self, ctx: &Context) -> Option<f64> {
        Some(torsional_band(ctx).1)
    }

    fn extend(&self, x: &mut Extension, roles: &Roles, ctx: &Context) -> Result<(), CauseError> {
        if roles.governor.is_none() {
            return Err(NotApplicable::NoBlock {
                role: Role::Governor,
                purpose: Some("to feed the turbine mass"),
            }
            .into());
        }
        if x.unit.block("shaft").is_some() {
            return Err(NotApplicable::NameTaken {
                name: "shaft".into(),
            }
            .into());
        }
        let h_path = format!("{}.h", roles.machine);
        let h = value(&x.unit, &h_path)?;
        // Split the calibrated (rigid) inertia: 15 % to the turbine to start with.
        let h_t = 0.15 * h;
        let (f_lo, f_hi) = torsional_band(ctx);
        // A resonance in the residual pins the frequency (the spectrum's resolution is a few
        // hundredths of a hertz): the re-fit searches within 2 % of it.
        let resonance = ctx
            .shaft_resonance
            .as_ref()
            .map(|p| p.freq_hz)
            .filter(|f| *f > f_lo && *f < f_hi);
        let f_start = resonance
            .or(ctx.mode_hint_hz.filter(|f| *f > f_lo && *f < f_hi))
            .unwrap_or(0.5 * f_hi);
        let (f_min, f_max) = match resonance {
            Some(f) => (0.98 * f, (1.02 * f).min(f_hi)),
            None => (f_lo, f_hi),
        };
        let shaft = new_block(
            "two_mass_shaft",
            &[
                ("h_turbine", h_t),
                ("h_generator", h - h_t),
                ("f_torsion_hz", f_start),
                ("zeta", 0.05),
                ("d_turbine", 0.0),
            ],
        )?;
        let h_r = x.unit.param(&h_path).map_err(CauseError::build)?;
        x.unit.set(h_r, h - h_t);
        add_block(&mut x.unit, "shaft", shaft)?;
        rewire(&mut x.unit, &roles.machine, &[("pm", "p_shaft")])?;
        // The frequency band comes from the resonance and the PMU rate, the turbine's share of
        // H from the unit's H (computed here); the damping ratio's range is declared.
        x.extension_free = vec![
            scanned(fb("shaft.f_torsion_hz", f_min, f_max, f_start)?, 48),
            declared(&x.unit, "shaft.zeta", 0.05)?,
            fb("shaft.h_turbine", 0.02 * h, 0.6 * h, h_t)?,
        ];
        x.interacting_free = vec![fb(&h_path, 0.4 * h, 1.05 * h, h - h_t)?];
        x.ties = vec![(h_path, "shaft.h_generator".into())];
        Ok(())
    }

    fn signature(&self, ev: &[EventEvidence], ctx: &Context) -> Vec<String> {
        let mut out = signature::dominant_p_mode(ev);
        if let Some(f) = ctx.mode_hint_hz {
            out.push(format!("search started at the residual's {f:.2} Hz mode"));
        }
        out
    }

    /// A torsional mode kept ringing by random turbine torque is a resonance in the P residual
    /// that no deterministic playback reproduces, so its re-fit gains nothing, while the
    /// spectrum shows it far above the measurement noise.
    fn named_by_evidence(&self, ctx: &Context) -> Option<String> {
        ctx.shaft_resonance.as_ref().map(|p| {
            format!(
                "the P residual has a resonance at {:.2} Hz with {:.1} times the band's noise power \
                 over {:.1} Hz ({:.1} times its neighbours'; chance from noise alone {:.1e}), which \
                 no deterministic playback reproduces: a shaft mode kept ringing by the turbine's \
                 torque",
                p.freq_hz, p.ratio, PEAK_WINDOW_HZ, p.prominence, p.p_value
            )
        })
    }

    /// A mode fitted at the lower edge of the torsional band is pressed against the slowest a
    /// shaft mode can be (`models.md` §12.1: hydro torsional modes lie above the 0.2-2 Hz
    /// electromechanical band): the residual asks for a slower effect, in the electromechanical
    /// band (the swing, the governor: a deadband's steps, a slow filter), which a "shaft" at the
    /// band's edge only mimics. "At the edge" as for any bound: within 0.1 % of the band's width
    /// ([`crate::problem::FreeParam::at_bound`]).
    ///
    /// And a mode fitted with a damping ratio above [`SHAFT_ZETA_MAX`] is no shaft mode: it does
    /// not ring, it filters the mechanical power (the residual asks for a lag or a slow dynamic
    /// elsewhere, which the two-mass shaft only mimics).
    fn unphysical(&self, fitted: &[(String, f64)], ctx: &Context) -> Option<String> {
        let f = fitted.iter().find(|(p, _)| p == "shaft.f_torsion_hz")?.1;
        let (f_lo, f_hi) = torsional_band(ctx);
        if f <= f_lo + 1e-3 * (f_hi - f_lo) {
            return Some(format!(
                "the fitted mode ({f:.2} Hz) sits at the lower edge of the torsional band ({f_lo:.1} Hz, the \
                 electromechanical band's upper edge): the residual asks for a slower effect, which a shaft mode \
                 does not explain"
            ));
        }
        let zeta = fitted.iter().find(|(p, _)| p == "shaft.zeta")?.1;
        (zeta > SHAFT_ZETA_MAX).then(|| {
            format!(
                "the fitted mode ({f:.2} Hz) has a damping ratio of {zeta:.3}, above the {SHAFT_ZETA_MAX} a \
                 turbine-generator shaft mode can have: it does not ring but filters the mechanical power, \
                 so the residual asks for another, slower effect"
            )
        })
    }

    fn scenario(&self, spread: &dyn Fn(u64) -> f64) -> Option<Scenario> {
        Some(Scenario {
            values: vec![
                ("shaft.f_torsion_hz", 5.0 + 2.0 * spread(1)),
                ("shaft.zeta", 0.02 + 0.01 * spread(2)),
                ("shaft.h_turbine", 0.8),
                ("machine.h", 3.7),
            ],
            key: Some(("shaft.f_torsion_hz", Tolerance::Rel(0.05))),
            kind: EventKind::FaultDip,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::catalog::cause;

    /// The veto every candidate's scoring asks (`Cause::vetoed`): a mode pressed against the
    /// band's lower edge is not named, one inside the band is, and the edge follows the PMU rate.
    #[test]
    fn a_mode_at_the_lower_edge_of_the_torsional_band_is_vetoed() {
        let mode = cause("torsional_mode").unwrap();
        let fitted = |f: f64| {
            vec![
                ("shaft.f_torsion_hz".to_string(), f),
                ("shaft.zeta".to_string(), 0.05),
                ("machine.h".to_string(), 3.0),
            ]
        };
        let ctx = |rate_hz: f64| Context {
            rate_hz,
            ..Default::default()
        };
        let why = mode.vetoed(&fitted(2.0), &ctx(60.0)).expect("vetoed");
        assert!(why.contains("lower edge"), "{why}");
        assert!(
            mode.vetoed(&fitted(2.02), &ctx(60.0)).is_some(),
            "within 0.1 % of 23 Hz"
        );
        assert!(mode.vetoed(&fitted(2.1), &ctx(60.0)).is_none());
        assert!(mode.vetoed(&fitted(11.5), &ctx(60.0)).is_none());
        // At 10 samples/s the band is 2-4.5 Hz: 2.01 Hz is at its edge, 2.1 Hz is not.
        assert!(mode.vetoed(&fitted(2.001), &ctx(10.0)).is_some());
        assert!(mode.vetoed(&fitted(2.1), &ctx(10.0)).is_none());
        // Without the frequency among the fitted values there is nothing to judge.
        assert!(mode
            .vetoed(&[("machine.h".to_string(), 3.0)], &ctx(60.0))
            .is_none());
    }

    /// A mode inside the band but damped above [`SHAFT_ZETA_MAX`] is no shaft mode: not named;
    /// lightly damped shaft modes (ζ 0.0005-0.05) are.
    #[test]
    fn a_heavily_damped_mode_is_no_shaft_mode() {
        let mode = cause("torsional_mode").unwrap();
        let fitted = |zeta: f64| {
            vec![
                ("shaft.f_torsion_hz".to_string(), 7.5),
                ("shaft.zeta".to_string(), zeta),
            ]
        };
        let ctx = Context {
            rate_hz: 60.0,
            ..Default::default()
        };
        let why = mode.vetoed(&fitted(0.48), &ctx).expect("vetoed");
        assert!(
            why.contains("damping ratio of 0.480") && why.contains("does not ring"),
            "{why}"
        );
        assert!(mode.vetoed(&fitted(0.12), &ctx).is_some());
        for zeta in [0.0005, 0.01, 0.042, 0.1] {
            assert!(mode.vetoed(&fitted(zeta), &ctx).is_none(), "ζ = {zeta}");
        }
    }
}
