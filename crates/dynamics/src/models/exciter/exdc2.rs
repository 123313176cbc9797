//! EXDC2: PSS/E's IEEE 1979 type DC2 (IEEE 421.5-2016 DC2C without its E_fd limits) DC-commutator
//! exciter whose regulator is supplied from the generator terminals: IEEEX1's block
//! (`ieeex1.rs`, where the equations, limits, initialisation and departures are written once)
//! with the regulator's non-windup limits proportional to the terminal voltage,
//!
//! ```text
//! T_A dV_R/dt = K_A y_ll − V_R     non-windup in [V_T·V_RMIN, V_T·V_RMAX]   (V_T: port v_supply [pu])
//! ```
//!
//! **Limits.** PSS/E's EXDC2 and IEEE 421.5 (DC2A/DC2C) draw `V_T·V_RMAX`, `V_T·V_RMIN` on the
//! regulator lag as a non-windup limit that moves with the terminal voltage: while V_R is held
//! on a limit it *is* the limit, `V_R = V_T(t)·V_RMAX`, and it leaves when its rate
//! `(K_A y_ll − V_R)/T_A` points back inside (IEEE 421.5-2016 Annex E's non-windup lag read with
//! a moving bound; [`NonWindup::derivative_moving`](crate::models::limiter::NonWindup::derivative_moving),
//! the switch located by an event). A ceiling that falls below a free V_R takes V_R down with
//! it while V_R still pushes outwards (no windup above the moving limit). A step-by-step
//! implementation that only resets a state found beyond its limit releases a pinned V_R when
//! the ceiling rises and lets it climb behind it with T_A: the two differ for a few T_A after a
//! rising ceiling (T_A is 0.01-0.06 s in the IEEE sample data).
//!
//! **Initialisation** as IEEEX1's; refused when `V_R0 = (K_E + S_E(E_fd0))·E_fd0` lies outside
//! `[V_T0·VRMIN, V_T0·VRMAX]`, naming V_T0.
//!
//! **Departures.** As IEEEX1 (SWITCH read and written back, not used). Same `.dyr` record
//! (CON order) and parameters as IEEEX1; typical values are IEEE 421.5-2005 Annex H's DC2A
//! sample data.
//!
//! **ANDES.** ANDES 2.0's `IEEEX1` is PSS/E's EXDC2 layout and declares the limits `V·V_RMAX`,
//! `V·V_RMIN`, but its anti-windup limiter keeps the constant `V_RMAX`, `V_RMIN` it was built
//! with (`LagAntiWindup` binds its bounds before `IEEEX1` replaces them): in a dip its V_R rises
//! to the unscaled `V_RMAX`, 0.2 pu of E_fd above ours after a 0.1 s dip to 0.6 pu. The ANDES
//! case (`tests/andes_models.rs`, `exdc2`) therefore keeps V_R inside `V_T·[V_RMIN, V_RMAX]`;
//! the scaled limits are tested on their own (`tests/exciters.rs`: the regulator pinned at
//! `V_T·V_RMAX` in a dip and at `V_T·V_RMIN` in an overvoltage).

use crate::dyr::DyrRecord;
use crate::models::exciter::ieeex1::{Ieeex1, DYR_CONS};
use crate::param_set;
use crate::registry::{ModelInfo, Role};

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "EXDC2",
    role: Role::Exciter,
    summary: "IEEE type DC2 DC exciter: IEEEX1 with regulator limits proportional to V_T",
    reference: "IEEE 1979 type DC2 as PSS/E EXDC2; non-windup V_R limits times V_T (ANDES IEEEX1 inside them)",
    make: || Box::new(exdc2()),
    dyr: Some(DyrRecord::cons(DYR_CONS)),
};

param_set! {
    /// EXDC2 parameters (PSS/E CON order, the fields of IEEEX1's `Ieeex1Params`). Typical
    /// values: IEEE 421.5-2005 Annex H sample data of DC2A; ranges as IEEEX1's.
    pub struct Exdc2Params {
        t_r: ("TR", "s", 0.0, (0.0, 0.06), "voltage transducer time constant T_R"),
        k_a: ("KA", "pu", 300.0, (10.0, 500.0), "regulator gain K_A"),
        t_a: ("TA", "s", 0.01, (0.0, 0.5), "regulator time constant T_A"),
        t_b: ("TB", "s", 0.0, (0.0, 20.0), "lead-lag lag time constant T_B (0: lead-lag bypassed)"),
        t_c: ("TC", "s", 0.0, (0.0, 10.0), "lead-lag lead time constant T_C"),
        vr_max: ("VRMAX", "pu", 4.95, (0.5, 10.0), "regulator maximum output V_RMAX, times V_T"),
        vr_min: ("VRMIN", "pu", -4.9, (-10.0, 0.0), "regulator minimum output V_RMIN, times V_T"),
        k_e: ("KE", "pu", 1.0, (-0.1, 1.0), "exciter field constant K_E (0: computed so that V_R0 = 0)"),
        t_e: ("TE", "s", 1.33, (0.2, 2.0), "exciter field time constant T_E"),
        k_f: ("KF", "pu", 0.1, (0.0, 0.3), "rate feedback gain K_F"),
        t_f1: ("TF1", "s", 0.675, (0.3, 3.0), "rate feedback time constant T_F1"),
        switch: ("SWITCH", "-", 0.0, (0.0, 1.0), "PSS/E SWITCH (read and written back, not used)"),
        e1: ("E1", "pu", 3.05, (1.0, 6.0), "exciter voltage E_1 of the first saturation point"),
        se1: ("SE1", "-", 0.279, (0.0, 1.0), "saturation factor S_E(E_1)"),
        e2: ("E2", "pu", 2.29, (1.0, 8.0), "exciter voltage E_2 of the second saturation point"),
        se2: ("SE2", "-", 0.117, (0.0, 2.0), "saturation factor S_E(E_2)"),
        v_ref_offset: ("dVref", "pu", 0.0, (-0.01, 0.01), "voltage reference offset added after initialisation (nuisance)"),
    }
}

/// An EXDC2 block with its typical parameters.
pub fn exdc2() -> Ieeex1 {
    Ieeex1::variant(&Exdc2Params::default(), true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block::Block;
    use crate::models::exciter::ieeex1::Ieeex1Params;

    #[test]
    fn exdc2_s_parameters_are_ieeex1_s_fields_with_dc2a_typical_values() {
        let (a, b) = (Exdc2Params::SPECS, Ieeex1Params::SPECS);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert_eq!((x.name, x.alias, x.unit, x.range), (y.name, y.alias, y.unit, y.range));
        }
        let blk = exdc2();
        assert_eq!(blk.model(), "EXDC2");
        assert_eq!(blk.params().specs()[1].typical, 300.0);
        assert_eq!(blk.p.k_a, 300.0);
        assert_eq!(Ieeex1::default().params().specs()[1].typical, 46.0);
    }
}
