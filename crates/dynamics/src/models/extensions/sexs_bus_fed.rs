//! `SEXS_bus_fed`: SEXS whose field-voltage limits follow the supply (terminal) voltage and the
//! field current, as for a thyristor exciter fed from the generator terminals (`models.md`
//! §12.3; ESST1A/SCRX-style ceiling).
//!
//! The SEXS equations are those of [`crate::models::exciter::sexs`] (one implementation,
//! [`SexsModel`], shared with SEXS); only the limits differ:
//!
//! ```text
//! v_err = V_ref + ΔV_ref − E_comp + V_S + V_UEL + V_OEL
//! T_B dx_ll/dt = v_err − x_ll,     y_ll = (T_A/T_B) v_err + (1 − T_A/T_B) x_ll
//! T_E dx_e/dt  = K y_ll − x_e      (non-windup in [E_fd,min(t), E_fd,max(t)])
//! E_fd,max(t) = V_t(t)·V_RMAX − K_C·X_adI_fd(t),    E_fd,min(t) = min(V_t(t)·V_RMIN, E_fd,max(t))
//! E_fd = clamp(x_e, E_fd,min, E_fd,max)
//! ```
//!
//! The limits move, so the non-windup logic is the moving-limit form of
//! [`NonWindup`](crate::models::limiter::NonWindup) (`derivative_moving`): while pinned the
//! exciter uses `x_e = E_fd,max(t)` exactly (the stored state tracks it with T_E and is projected
//! onto it at every mode change); it leaves the limit when `K y_ll` falls below the limit. V_t is
//! read on port `v_supply` (default: the played-back `v_term`), separate from the regulated
//! `v_term` (E_comp) so that a load compensator can be wired in front of the regulator without
//! changing the supply.
//!
//! Initialisation as SEXS; infeasible (an error) when `E_fd0` lies outside the limits at the
//! operating point. With `K_C = 0` and `V_RMAX`, `V_RMIN` far away it behaves as SEXS with
//! limits that are never reached.

use crate::block::{guard, Io, ModelError, Port, PortInit};
use crate::models::exciter::roles::{ExciterRoles, ParamRole};
use crate::models::exciter::sexs::{
    port, sexs_roles, SexsEq, SexsGains, SexsModel, SexsVariant, PORTS as SEXS_PORTS,
};
use crate::param_set;
use crate::sens::Scalar;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "SEXS_bus_fed",
    role: Role::Exciter,
    summary: "SEXS with a bus-fed ceiling V_t·VRMAX − KC·X_adI_fd (extension, models.md §12.3)",
    reference: "models.md §12.3 (SEXS with an ST1A-style bus-fed ceiling)",
    make: || Box::new(SexsBusFed::default()),
    dyr: None,
};

param_set! {
    /// SEXS_bus_fed parameters.
    pub struct SexsBusFedParams {
        ta_tb: ("T_AT_B", "-", 0.2, (0.1, 0.3), "ratio of lead to lag time constant T_A/T_B"),
        tb: ("T_B", "s", 10.0, (5.0, 15.0), "lag time constant T_B"),
        k: ("K", "pu", 100.0, (30.0, 400.0), "gain"),
        te: ("T_E", "s", 0.05, (0.02, 0.1), "exciter (bridge) time constant"),
        vr_min: ("VRMIN", "pu", 0.0, (-5.0, 0.0), "minimum field voltage per pu supply voltage"),
        vr_max: ("VRMAX", "pu", 5.0, (4.0, 7.0), "maximum field voltage per pu supply voltage"),
        k_c: ("KC", "pu", 0.1, (0.0, 0.2), "rectifier commutation (loading) factor on X_adI_fd"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

const V_SUPPLY: usize = 5;
const XADIFD: usize = 6;

const PORTS: &[Port] = &[
    SEXS_PORTS[port::V_TERM],
    SEXS_PORTS[port::VS],
    SEXS_PORTS[port::VOEL],
    SEXS_PORTS[port::VUEL],
    SEXS_PORTS[port::EFD],
    Port::input_ft(
        "v_supply",
        PortInit::Needs,
        "supply (terminal) voltage V_t of the rectifier [pu]",
    )
    .wired("v_term"),
    Port::input_ft("xadifd", PortInit::Needs, "field current X_ad I_fd [pu]"),
];

impl<S: Scalar> SexsEq<S> for SexsBusFedParams<S> {
    #[inline(always)]
    fn gains(&self) -> SexsGains<S> {
        SexsGains {
            ta_tb: self.ta_tb,
            tb: self.tb,
            k: self.k,
            te: self.te,
            v_ref_offset: self.v_ref_offset,
        }
    }
    /// `(E_fd,min, E_fd,max)`, never upside down: in a deep dip with a high field current the
    /// commutation drop can take the ceiling `V_t·V_RMAX − K_C·X_adI_fd` below the floor
    /// `V_t·V_RMIN`; the bridge then delivers the ceiling (the drop acts whatever the firing
    /// angle, so no angle reaches the floor), i.e. the floor follows the ceiling down.
    #[inline(always)]
    fn limits(&self, io: &Io<S>) -> (S, S) {
        let v = io.get(V_SUPPLY);
        let hi = v * self.vr_max - self.k_c * io.get(XADIFD);
        ((v * self.vr_min).min_s(hi), hi)
    }
}

impl SexsVariant for SexsBusFedParams {
    const MODEL: &'static str = "SEXS_bus_fed";
    const PORTS: &'static [Port] = PORTS;
    const MOVING_LIMITS: bool = true;
    fn validate_limits(&self) -> Result<(), ModelError> {
        guard::finite("vr_min", self.vr_min)?;
        guard::non_negative("k_c", self.k_c)?;
        guard::greater("vr_max", self.vr_max, "vr_min", self.vr_min)
    }
    fn describe_limits(&self, io: &Io) -> String {
        let (lo, hi) = self.limits(io);
        format!(
            "[V_t·VRMIN, V_t·VRMAX − KC·X_adI_fd] = [{lo:.4}, {hi:.4}] (V_t = {:.4}, X_adI_fd = {:.4})",
            io.get(V_SUPPLY),
            io.get(XADIFD)
        )
    }
    fn roles() -> ExciterRoles {
        let mut r = sexs_roles("SEXS_bus_fed");
        r.ceiling = ParamRole::none(
            "SEXS_bus_fed's ceiling is V_t·VRMAX − KC·X_adI_fd, not one parameter (see supply_ceiling)",
        );
        r.floor = ParamRole::none(
            "SEXS_bus_fed's floor is V_t·VRMIN, not one parameter (see supply_floor)",
        );
        r.supply_ceiling = ParamRole::param("vr_max");
        r.supply_floor = ParamRole::param("vr_min");
        r.commutation = ParamRole::param("k_c");
        r
    }
}

/// The bus-fed SEXS block.
pub type SexsBusFed = SexsModel<SexsBusFedParams>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block::Block;

    #[test]
    fn roles_name_the_supply_fed_limits() {
        let b = SexsBusFed::default();
        let r = b.exciter_roles().unwrap();
        r.check(b.params()).unwrap();
        assert_eq!(r.gain.name(), Some("k"));
        assert_eq!(r.field_time_constant.name(), Some("te"));
        assert!(r.ceiling.name().is_none() && r.floor.name().is_none());
        assert!(r.ceiling.reason().unwrap().contains("V_t·VRMAX"));
        assert_eq!(r.supply_ceiling.name(), Some("vr_max"));
        assert_eq!(r.supply_floor.name(), Some("vr_min"));
        assert_eq!(r.commutation.name(), Some("k_c"));
        assert_eq!(r.transient_gain_reduction.names(), Some(("ta_tb", "tb")));
    }

    /// An integrator's trial stage may hand the block non-finite signals (a diverging
    /// candidate); the limits are then NaN, and the block must answer with numbers or NaN for
    /// the integrator to reject the step, never panic (`f64::clamp` panics on a NaN limit).
    #[test]
    fn non_finite_supply_or_field_current_does_not_panic() {
        let mut b = SexsBusFed::new(SexsBusFedParams::default());
        let map: Vec<usize> = (0..PORTS.len()).collect();
        for (v, i) in [
            (f64::NAN, 2.0),
            (1.0, f64::NAN),
            (f64::INFINITY, 2.0),
            (1.0, f64::INFINITY),
            (0.2, 1e3), // a ceiling far below the floor
        ] {
            let mut bus = vec![0.0; PORTS.len()];
            bus[port::V_TERM] = 1.0;
            bus[V_SUPPLY] = v;
            bus[XADIFD] = i;
            let mut x = [0.02, 2.0];
            let mut dx = [0.0; 2];
            let mut g = [0.0; 2];
            b.outputs(0.0, &x, &mut Io::new(&mut bus, &map));
            let efd = bus[port::EFD];
            let io = Io::new(&mut bus, &map);
            b.derivatives(0.0, &x, &io, &mut dx);
            b.events(&x, &io, &mut g);
            b.update_modes(&mut x, &io);
            let (lo, hi) = b.p.limits(&io);
            assert!(
                !(lo > hi),
                "limits upside down: [{lo}, {hi}] (V_t {v}, X_adI_fd {i})"
            );
            if hi.is_finite() {
                assert!(efd <= hi, "E_fd {efd} above the ceiling {hi}");
            }
        }
    }
}
