//! GENCLS: classical machine, constant voltage E' behind X'd (`models.md` §7).
//!
//! States: `δ, Δω`. The stator is `v_q = E' − R_a i_q − X'd i_d`, `v_d = X'd i_q − R_a i_d`,
//! i.e. the common stator solve with `E''_d = 0`, `E''_q = E'`, `X''_d = X''_q = X'd`.
//! `E' = |V + (R_a + jX'd) I|` is fixed at initialisation. The swing equation is the common one
//! (PSS/E GENSAL form, machine base), not OpenIPSL's system-base GENCLS variant (documented
//! departure: OpenIPSL's form is only consistent when the machine base equals the system base).
//! GENCLS has no field winding: an exciter cannot be attached (the unit rejects it).

use super::{Electrical, ElectricalEq, ElectricalInit, Field, Phasor, Stator, StatorImpedance};
use crate::block::{guard, ModelError};
use crate::param_set;
use crate::params::ParamSet;
use crate::sens::{Scalar, D};
use crate::dyr::{DyrRecord, MachineFields, ZsorceX};
use crate::registry::{ModelInfo, Role};
use super::Machine;

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "GENCLS",
    role: Role::Machine,
    summary: "classical machine, constant E' behind X'd",
    reference: "PSS/E GENCLS (models.md §7)",
    make: || Box::new(Machine::new(Gencls::default())),
    dyr: Some(DyrRecord {
        icons: &[],
        cons: &["h", "d"],
        machine: Some(MachineFields {
            zsorce_x: ZsorceX::Sets("x_d_prime"),
            ties: &[],
        }),
    }),
};

param_set! {
    /// GENCLS parameters (machine base).
    pub struct GenclsParams {
        h: ("H", "s", 4.5, (3.0, 6.0), "inertia constant on the machine base"),
        d: ("D", "pu", 0.0, (0.0, 2.0), "speed damping (pu power per pu speed)"),
        x_d_prime: ("Xpd", "pu", 0.30, (0.25, 0.40), "d-axis transient reactance X'd"),
        r_a: ("R_a", "pu", 0.002, (0.0, 0.005), "armature resistance"),
    }
}

/// GENCLS electrical model (on `f64`; on [`D`] for forward sensitivities).
#[derive(Debug, Clone)]
pub struct Gencls<S = f64> {
    pub p: GenclsParams<S>,
    /// Internal voltage E' [pu], set at initialisation.
    e_prime: S,
    z: StatorImpedance<S>,
}

impl<S: Scalar> ElectricalEq<S> for Gencls<S> {
    fn inertia_damping(&self) -> (S, S) {
        (self.p.h, self.p.d)
    }
    #[inline(always)]
    fn stator(&self, _x: &[S], vd: S, vq: S) -> Stator<S> {
        Stator::solve(S::cst(0.0), self.e_prime, vd, vq, &self.z)
    }
    fn field(&self, _x: &[S], _st: &Stator<S>) -> Field<S> {
        Field {
            xadifd: self.e_prime,
            sat: S::cst(0.0),
        }
    }
    fn derivatives(&self, _x: &[S], _efd: S, _field: Field<S>, _st: &Stator<S>, _dx: &mut [S]) {}
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
    type Lifted = Gencls<D>;

    fn params(&self) -> &dyn ParamSet {
        &self.p
    }
    fn params_mut(&mut self) -> &mut dyn ParamSet {
        &mut self.p
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
    fn init_constants(&self) -> Vec<f64> {
        vec![self.e_prime]
    }
    fn lift(&self, lanes: &[Option<usize>], consts: &[D]) -> Option<Gencls<D>> {
        let p = self.p.lift_dual(lanes);
        let z = StatorImpedance::new(p.r_a, p.x_d_prime, p.x_d_prime);
        let e_prime = consts.first().copied().unwrap_or(D::cst(self.e_prime));
        Some(Gencls { p, e_prime, z })
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
}

impl Default for Gencls {
    fn default() -> Self {
        Self::new(Default::default())
    }
}
