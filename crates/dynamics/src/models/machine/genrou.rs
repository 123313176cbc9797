//! GENROU: round-rotor machine with quadratic saturation on both axes (`models.md` §6).
//!
//! States: `δ, Δω, E'_q, E'_d, ψ_kd, ψ_kq`. PSS/E's GENROU has a single subtransient reactance
//! X'' (= X''d = X''q), as has ANDES; so does this model (`x_d_pp`).
//!
//! ```text
//! K3d = (X'' − Xl)/(X'd − Xl), K4d = (X'd − X'')/(X'd − Xl), K1d = (X'd − X'')(Xd − X'd)/(X'd − Xl)²
//! K3q = (X'' − Xl)/(X'q − Xl), K4q = (X'q − X'')/(X'q − Xl), K1q = (X'q − X'')(Xq − X'q)/(X'q − Xl)²
//! E''_q = K3d E'_q + K4d ψ_kd,   E''_d = K3q E'_d + K4q ψ_kq,   Se = Se_quad(|ψ''|),  γ = (Xq − Xl)/(Xd − Xl)
//! X_adI_fd = E'_q + K1d (E'_q − ψ_kd − (X'd − Xl) i_d) + (Xd − X'd) i_d + Se E''_q
//! X_aqI_1q = E'_d + K1q (E'_d − ψ_kq + (X'q − Xl) i_q) − (Xq − X'q) i_q + γ Se E''_d
//! T'd0 dE'_q/dt = E_fd − X_adI_fd          T'q0 dE'_d/dt = −X_aqI_1q
//! T''d0 dψ_kd/dt = E'_q − ψ_kd − (X'd − Xl) i_d
//! T''q0 dψ_kq/dt = E'_d − ψ_kq + (X'q − Xl) i_q
//! ```
//!
//! With X'q = Xq and no saturation the q-axis reduces to GENSAL's single subtransient circuit
//! (E'_d decays to 0), which is how ANDES represents a salient-pole unit.

use super::saturation::QuadraticSaturation;
use super::{
    check_d_axis, norm2, DAxis, Electrical, ElectricalEq, ElectricalInit, Field, Phasor, Stator,
    StatorImpedance,
};
use crate::block::{guard, ModelError};
use crate::param_set;
use crate::params::ParamSet;
use crate::sens::{Scalar, D};
use crate::dyr::{DyrRecord, MachineFields, ZsorceX};
use crate::registry::{ModelInfo, Role};
use super::Machine;

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "GENROU",
    role: Role::Machine,
    summary: "round-rotor machine, quadratic saturation on |ψ''|",
    reference: "PSS/E GENROU (models.md §6); ANDES GENROU",
    make: || Box::new(Machine::new(Genrou::default())),
    dyr: Some(DyrRecord {
        icons: &[],
        cons: &[
            "t_d0_prime",
            "t_d0_pp",
            "t_q0_prime",
            "t_q0_pp",
            "h",
            "d",
            "x_d",
            "x_q",
            "x_d_prime",
            "x_q_prime",
            "x_d_pp",
            "x_l",
            "s10",
            "s12",
        ],
        machine: Some(MachineFields {
            zsorce_x: ZsorceX::Equals("x_d_pp"),
            ties: &[],
        }),
    }),
};

param_set! {
    /// GENROU parameters (machine base).
    pub struct GenrouParams {
        t_d0_prime: ("Tpd0", "s", 7.0, (5.0, 10.0), "d-axis transient open-circuit time constant T'd0"),
        t_d0_pp: ("Tppd0", "s", 0.05, (0.03, 0.08), "d-axis subtransient open-circuit time constant T''d0"),
        t_q0_prime: ("Tpq0", "s", 0.7, (0.4, 1.0), "q-axis transient open-circuit time constant T'q0"),
        t_q0_pp: ("Tppq0", "s", 0.1, (0.05, 0.2), "q-axis subtransient open-circuit time constant T''q0"),
        h: ("H", "s", 4.5, (3.0, 6.0), "inertia constant on the machine base"),
        d: ("D", "pu", 0.0, (0.0, 2.0), "speed damping (pu power per pu speed)"),
        x_d: ("Xd", "pu", 0.95, (0.8, 2.0), "d-axis synchronous reactance"),
        x_q: ("Xq", "pu", 0.65, (0.5, 1.9), "q-axis synchronous reactance"),
        x_d_prime: ("Xpd", "pu", 0.30, (0.2, 0.4), "d-axis transient reactance X'd"),
        x_q_prime: ("Xpq", "pu", 0.5, (0.3, 0.7), "q-axis transient reactance X'q"),
        x_d_pp: ("Xppd", "pu", 0.22, (0.15, 0.28), "subtransient reactance X'' (both axes)"),
        x_l: ("Xl", "pu", 0.15, (0.10, 0.20), "stator leakage reactance"),
        s10: ("S10", "-", 0.1, (0.0, 0.4), "saturation factor at 1.0 pu flux"),
        s12: ("S12", "-", 0.3, (0.02, 1.5), "saturation factor at 1.2 pu flux"),
        r_a: ("R_a", "pu", 0.002, (0.001, 0.005), "armature resistance"),
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    z: StatorImpedance<S>,
    d: DAxis<S>,
    k1q: S,
    k3q: S,
    k4q: S,
    gamma: S,
    sat: QuadraticSaturation<S>,
}

impl<S: Scalar> Consts<S> {
    fn of(p: &GenrouParams<S>) -> Result<Self, ModelError> {
        let xql = p.x_q_prime - p.x_l;
        Ok(Self {
            z: StatorImpedance::new(p.r_a, p.x_d_pp, p.x_d_pp),
            d: DAxis::new(p.x_d, p.x_d_prime, p.x_d_pp, p.x_l),
            k1q: (p.x_q_prime - p.x_d_pp) * (p.x_q - p.x_q_prime) / (xql * xql),
            k3q: (p.x_d_pp - p.x_l) / xql,
            k4q: (p.x_q_prime - p.x_d_pp) / xql,
            gamma: (p.x_q - p.x_l) / (p.x_d - p.x_l),
            sat: QuadraticSaturation::new(p.s10, p.s12)?,
        })
    }
}

/// GENROU electrical model (on `f64`; on [`D`] for forward sensitivities).
#[derive(Debug, Clone)]
pub struct Genrou<S = f64> {
    pub p: GenrouParams<S>,
    k: Consts<S>,
}

impl Genrou {
    pub fn new(p: GenrouParams) -> Self {
        Self {
            p,
            k: Consts::default(),
        }
    }
}

impl<S: Scalar> Genrou<S> {
    #[inline(always)]
    fn subtransient(&self, x: &[S]) -> (S, S) {
        let k = &self.k;
        (k.k3q * x[1] + k.k4q * x[3], k.d.k3d * x[0] + k.d.k4d * x[2])
    }
}

impl<S: Scalar> ElectricalEq<S> for Genrou<S> {
    fn inertia_damping(&self) -> (S, S) {
        (self.p.h, self.p.d)
    }

    #[inline(always)]
    fn stator(&self, x: &[S], vd: S, vq: S) -> Stator<S> {
        let (e_d_pp, e_q_pp) = self.subtransient(x);
        Stator::solve(e_d_pp, e_q_pp, vd, vq, &self.k.z)
    }

    #[inline(always)]
    fn field(&self, x: &[S], st: &Stator<S>) -> Field<S> {
        let (p, k) = (&self.p, &self.k);
        let (e_d_pp, e_q_pp) = self.subtransient(x);
        let se = k.sat.eval(norm2(e_q_pp, e_d_pp));
        let xadifd = x[0]
            + k.d.k1d * (x[0] - x[2] - (p.x_d_prime - p.x_l) * st.id)
            + (p.x_d - p.x_d_prime) * st.id
            + se * e_q_pp;
        Field { xadifd, sat: se }
    }

    #[inline(always)]
    fn derivatives(&self, x: &[S], efd: S, field: Field<S>, st: &Stator<S>, dx: &mut [S]) {
        let (p, k) = (&self.p, &self.k);
        let (e_d_pp, _) = self.subtransient(x);
        let (xadifd, se) = (field.xadifd, field.sat);
        let xaqi1q = x[1] + k.k1q * (x[1] - x[3] + (p.x_q_prime - p.x_l) * st.iq)
            - (p.x_q - p.x_q_prime) * st.iq
            + k.gamma * se * e_d_pp;
        dx[0] = (efd - xadifd) / p.t_d0_prime;
        dx[1] = -xaqi1q / p.t_q0_prime;
        dx[2] = (x[0] - x[2] - (p.x_d_prime - p.x_l) * st.id) / p.t_d0_pp;
        dx[3] = (x[1] - x[3] + (p.x_q_prime - p.x_l) * st.iq) / p.t_q0_pp;
    }
}

impl Electrical for Genrou {
    const MODEL: &'static str = "GENROU";
    type Lifted = Genrou<D>;
    const STATE_NAMES: &'static [&'static str] = &[
        "delta",
        "speed",
        "e_q_prime",
        "e_d_prime",
        "psi_kd",
        "psi_kq",
    ];

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
        let p = &self.p;
        guard::positive("t_d0_prime", p.t_d0_prime)?;
        guard::positive("t_d0_pp", p.t_d0_pp)?;
        // The transient flux decays slower than the subtransient one (T'd0 > T''d0).
        guard::greater("t_d0_prime", p.t_d0_prime, "t_d0_pp", p.t_d0_pp)?;
        guard::positive("t_q0_prime", p.t_q0_prime)?;
        guard::positive("t_q0_pp", p.t_q0_pp)?;
        check_d_axis(p.x_d, p.x_d_prime, p.x_d_pp, p.x_l)?;
        guard::greater("x_q_prime", p.x_q_prime, "x_d_pp", p.x_d_pp)?;
        guard::greater_eq("x_q", p.x_q, "x_q_prime", p.x_q_prime)?;
        QuadraticSaturation::new(p.s10, p.s12).map(|_| ())
    }

    fn prepare(&mut self) -> Result<(), ModelError> {
        self.k = Consts::of(&self.p)?;
        Ok(())
    }

    fn lift(&self, lanes: &[Option<usize>], _consts: &[D]) -> Option<Genrou<D>> {
        let p = self.p.lift_dual(lanes);
        let k = Consts::of(&p).ok()?;
        Some(Genrou { p, k })
    }

    fn init_electrical(
        &mut self,
        v: Phasor,
        i: Phasor,
        x: &mut [f64],
    ) -> Result<ElectricalInit, ModelError> {
        let p = &self.p;
        let k = &self.k;
        let xpp = p.x_d_pp;
        // Closed form (§5.2 / §6), exact with a single X''.
        let psi_pp = v + Phasor::new(p.r_a, xpp) * i;
        let theta_psi = psi_pp.arg();
        let alpha = theta_psi - i.arg();
        let se0 = k.sat.eval(psi_pp.abs());
        let a = psi_pp.abs() * (1.0 + k.gamma * se0);
        let b = i.abs() * (xpp - p.x_q);
        let delta = theta_psi - (b * alpha.cos()).atan2(a - b * alpha.sin());
        let (vd, vq) = v.to_dq(delta);
        let (id, iq) = i.to_dq(delta);
        let e_q_pp = vq + xpp * id + p.r_a * iq;
        let e_d_pp = vd - xpp * iq + p.r_a * id;
        let e_q_p = e_q_pp + (p.x_d_prime - xpp) * id;
        let psi_kd = e_q_p - (p.x_d_prime - p.x_l) * id;
        let psi_kq = e_d_pp + (xpp - p.x_l) * iq;
        let e_d_p = psi_kq - (p.x_q_prime - p.x_l) * iq;
        x[0] = e_q_p;
        x[1] = e_d_p;
        x[2] = psi_kd;
        x[3] = psi_kq;
        let efd = (1.0 + se0) * e_q_pp + (p.x_d - xpp) * id;
        Ok(ElectricalInit { delta, efd })
    }
}

impl Default for Genrou {
    fn default() -> Self {
        Self::new(Default::default())
    }
}
