//! GENCLS: classical machine, constant voltage E' behind X'd (`models.md` §7).
//!
//! States: `δ, Δω`. The stator is `v_q = E' − R_a i_q − X'd i_d`, `v_d = X'd i_q − R_a i_d`,
//! i.e. the common stator solve with `E''_d = 0`, `E''_q = E'`, `X''_d = X''_q = X'd`.
//! `E' = |V + (R_a + jX'd) I|` is fixed at initialisation. The swing equation is the common one
//! (PSS/E GENSAL form, machine base), not OpenIPSL's system-base GENCLS variant (documented
//! departure: OpenIPSL's form is only consistent when the machine base equals the system base).
//! GENCLS has no field winding: an exciter cannot be attached (the unit rejects it).

use super::{Electrical, ElectricalInit, Field, Phasor, Stator, StatorImpedance};
use crate::block::{guard, ModelError};
use crate::param_set;
use crate::params::ParamSet;

param_set! {
    /// GENCLS parameters (machine base).
    pub struct GenclsParams {
        h: ("H", "s", 4.5, (3.0, 6.0), "inertia constant on the machine base"),
        d: ("D", "pu", 0.0, (0.0, 2.0), "speed damping (pu power per pu speed)"),
        x_d_prime: ("Xpd", "pu", 0.30, (0.25, 0.40), "d-axis transient reactance X'd"),
        r_a: ("R_a", "pu", 0.002, (0.0, 0.005), "armature resistance"),
    }
}

/// GENCLS electrical model.
#[derive(Debug, Clone, Default)]
pub struct Gencls {
    pub p: GenclsParams,
    /// Internal voltage E' [pu], set at initialisation.
    e_prime: f64,
    z: StatorImpedance,
}

impl Gencls {
    pub fn new(p: GenclsParams) -> Self {
        Self {
            p,
            e_prime: 0.0,
            z: StatorImpedance::default(),
        }
    }
}

impl Electrical for Gencls {
    const MODEL: &'static str = "GENCLS";
    const STATE_NAMES: &'static [&'static str] = &["delta", "speed"];

    fn params(&self) -> &dyn ParamSet {
        &self.p
    }
    fn params_mut(&mut self) -> &mut dyn ParamSet {
        &mut self.p
    }
    fn inertia_damping(&self) -> (f64, f64) {
        (self.p.h, self.p.d)
    }
    fn armature_resistance(&self) -> f64 {
        self.p.r_a
    }
    fn validate(&self) -> Result<(), ModelError> {
        guard::positive("x_d_prime", self.p.x_d_prime)
    }
    fn prepare(&mut self) -> Result<(), ModelError> {
        self.z = StatorImpedance::new(self.p.r_a, self.p.x_d_prime, self.p.x_d_prime);
        Ok(())
    }
    fn init_electrical(
        &mut self,
        v: Phasor,
        i: Phasor,
        _x: &mut [f64],
    ) -> Result<ElectricalInit, ModelError> {
        let e = v + Phasor::new(self.p.r_a, self.p.x_d_prime) * i;
        self.e_prime = e.abs();
        Ok(ElectricalInit {
            delta: e.arg(),
            efd: self.e_prime,
        })
    }
    #[inline(always)]
    fn stator(&self, _x: &[f64], vd: f64, vq: f64) -> Stator {
        Stator::solve(0.0, self.e_prime, vd, vq, &self.z)
    }
    fn field(&self, _x: &[f64], _st: &Stator) -> Field {
        Field {
            xadifd: self.e_prime,
            sat: 0.0,
        }
    }
    fn derivatives(&self, _x: &[f64], _efd: f64, _field: Field, _st: &Stator, _dx: &mut [f64]) {}
}
