//! GENSAL: salient-pole machine with quadratic saturation on the d-axis (`models.md` §4).
//!
//! States: `δ, Δω, E'_q, ψ_kd, E''_d`. Saturation acts on the d-axis only and its input is the
//! transient voltage `E'_q` (OpenIPSL `GENSAL.mo`, OPAL-RT agrees):
//!
//! ```text
//! K3d = (X''d − Xl)/(X'd − Xl),  K4d = (X'd − X''d)/(X'd − Xl),  K1d = (X'd − X''d)(Xd − X'd)/(X'd − Xl)²
//! E''_q = K3d E'_q + K4d ψ_kd
//! X_adI_fd = K1d (E'_q − ψ_kd − (X'd − Xl) i_d) + (Xd − X'd) i_d + (1 + Se(E'_q)) E'_q
//! T'd0  dE'_q/dt = E_fd − X_adI_fd
//! T''d0 dψ_kd/dt = E'_q − ψ_kd − (X'd − Xl) i_d
//! T''q0 dE''_d/dt = −E''_d + (Xq − X''q) i_q
//! ```
//!
//! Initialisation (§4.3): `δ0 = arg(V + (R_a + jXq) I)` (exact for any X''q), then the states in
//! closed form and `E_fd0 = (1 + Se(E'_q0)) E'_q0 + (Xd − X'd) i_d0`.
//!
//! **X''q.** As in OpenIPSL's GENSAL (`Xppq`) and `models.md` §4, X''q is a parameter of its own:
//! the stator equations use X''d on the d-axis and X''q on the q-axis (subtransient saliency,
//! solved exactly in dq, §1.2) and the q-axis circuit is `T''q0 dE''_d/dt = −E''_d + (Xq − X''q)
//! i_q`. PSS/E's GENSAL record has a single X'' for both axes: a `.dyr` record sets X''q = X''d,
//! and writing a unit with X''q ≠ X''d as `.dyr` warns that X''q is lost. RaPId's Mostar unit
//! (OpenIPSL GENSAL with X''d = 0.215, X''q = 0.241 and R_a = 0.017637 Ω/(10.5² kV²/30 MVA) =
//! 0.0048 pu) therefore runs here as in OpenIPSL; in PSS/E the same record would give
//! X''q = 0.215. R_a enters the stator equations and `P_m0 = P0 + R_a |I|²`; the steady start is
//! exact for any X''q and R_a (`tests/steady_state.rs`).

use super::saturation::QuadraticSaturation;
use super::{
    check_d_axis, Electrical, ElectricalEq, ElectricalInit, Field, Phasor, SalientConsts, Stator,
};
use crate::block::{guard, ModelError};
use crate::param_set;
use crate::params::ParamSet;
use crate::sens::{Scalar, D};
use crate::dyr::{DyrRecord, MachineFields, ZsorceX, ONE_X_PP};
use crate::registry::{ModelInfo, Role};
use super::Machine;

/// The registry entry ([`crate::registry`]): name, role, `.dyr` record.
pub const MODEL: ModelInfo = ModelInfo {
    name: "GENSAL",
    role: Role::Machine,
    summary: "salient-pole machine, quadratic saturation on E'q (d-axis)",
    reference: "PSS/E GENSAL as OpenIPSL implements it (models.md §4)",
    make: || Box::new(Machine::new(Gensal::default())),
    dyr: Some(DyrRecord {
        icons: &[],
        cons: &[
            "t_d0_prime",
            "t_d0_pp",
            "t_q0_pp",
            "h",
            "d",
            "x_d",
            "x_q",
            "x_d_prime",
            "x_d_pp",
            "x_l",
            "s10",
            "s12",
        ],
        machine: Some(MachineFields {
            zsorce_x: ZsorceX::Equals("x_d_pp"),
            ties: &[ONE_X_PP],
        }),
    }),
};

param_set! {
    /// GENSAL parameters (machine base). Typical values: large hydro unit (`models.md` §4.1).
    pub struct GensalParams {
        t_d0_prime: ("Tpd0", "s", 7.0, (5.0, 10.0), "d-axis transient open-circuit time constant T'd0"),
        t_d0_pp: ("Tppd0", "s", 0.05, (0.03, 0.08), "d-axis subtransient open-circuit time constant T''d0"),
        t_q0_pp: ("Tppq0", "s", 0.1, (0.05, 0.2), "q-axis subtransient open-circuit time constant T''q0"),
        h: ("H", "s", 4.5, (3.0, 6.0), "inertia constant on the machine base"),
        d: ("D", "pu", 0.0, (0.0, 2.0), "speed damping (pu power per pu speed)"),
        x_d: ("Xd", "pu", 0.95, (0.8, 1.2), "d-axis synchronous reactance"),
        x_q: ("Xq", "pu", 0.65, (0.5, 0.75), "q-axis synchronous reactance"),
        x_d_prime: ("Xpd", "pu", 0.30, (0.25, 0.40), "d-axis transient reactance X'd"),
        x_d_pp: ("Xppd", "pu", 0.22, (0.15, 0.28), "d-axis subtransient reactance X''d"),
        x_q_pp: ("Xppq", "pu", 0.22, (0.15, 0.28), "q-axis subtransient reactance X''q (PSS/E: = X''d)"),
        x_l: ("Xl", "pu", 0.15, (0.10, 0.20), "stator leakage reactance"),
        s10: ("S10", "-", 0.1, (0.0, 0.4), "saturation factor at 1.0 pu flux"),
        s12: ("S12", "-", 0.3, (0.02, 1.5), "saturation factor at 1.2 pu flux"),
        r_a: ("R_a", "pu", 0.002, (0.001, 0.005), "armature resistance"),
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Consts<S = f64> {
    /// The stator and d-axis constants (shared with GENSAE).
    s: SalientConsts<S>,
    sat: QuadraticSaturation<S>,
}

impl<S: Scalar> Consts<S> {
    fn of(p: &GensalParams<S>) -> Result<Self, ModelError> {
        Ok(Self {
            s: SalientConsts::of(p.into()),
            sat: QuadraticSaturation::new(p.s10, p.s12)?,
        })
    }
}

/// GENSAL electrical model (on `f64`; on [`D`] for forward sensitivities).
#[derive(Debug, Clone)]
pub struct Gensal<S = f64> {
    pub p: GensalParams<S>,
    k: Consts<S>,
}

impl<S: Scalar> ElectricalEq<S> for Gensal<S> {
    fn inertia_damping(&self) -> (S, S) {
        (self.p.h, self.p.d)
    }

    #[inline(always)]
    fn stator(&self, x: &[S], vd: S, vq: S) -> Stator<S> {
        let e_q_pp = self.k.s.d.k3d * x[0] + self.k.s.d.k4d * x[1];
        Stator::solve(x[2], e_q_pp, vd, vq, &self.k.s.z)
    }

    #[inline(always)]
    fn field(&self, x: &[S], st: &Stator<S>) -> Field<S> {
        let (p, k) = (&self.p, &self.k);
        let se = k.sat.eval(x[0]);
        let xadifd = k.s.d.k1d * (x[0] - x[1] - (p.x_d_prime - p.x_l) * st.id)
            + (p.x_d - p.x_d_prime) * st.id
            + (se + 1.0) * x[0];
        Field { xadifd, sat: se }
    }

    #[inline(always)]
    fn derivatives(&self, x: &[S], efd: S, field: Field<S>, st: &Stator<S>, dx: &mut [S]) {
        let (p, k) = (&self.p, &self.k);
        dx[0] = (efd - field.xadifd) * k.s.inv_t_d0_prime;
        dx[1] = (x[0] - x[1] - (p.x_d_prime - p.x_l) * st.id) * k.s.inv_t_d0_pp;
        dx[2] = ((p.x_q - p.x_q_pp) * st.iq - x[2]) * k.s.inv_t_q0_pp;
    }
}

impl Gensal {
    pub fn new(p: GensalParams) -> Self {
        Self {
            p,
            k: Consts::default(),
        }
    }
}

impl Electrical for Gensal {
    const MODEL: &'static str = "GENSAL";
    const STATE_NAMES: &'static [&'static str] =
        &["delta", "speed", "e_q_prime", "psi_kd", "e_d_pp"];
    type Lifted = Gensal<D>;

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
        guard::positive("t_q0_pp", p.t_q0_pp)?;
        check_d_axis(p.x_d, p.x_d_prime, p.x_d_pp, p.x_l)?;
        guard::greater("x_q_pp", p.x_q_pp, "x_l", p.x_l)?;
        guard::greater("x_q", p.x_q, "x_q_pp", p.x_q_pp)?;
        QuadraticSaturation::new(p.s10, p.s12).map(|_| ())
    }

    fn prepare(&mut self) -> Result<(), ModelError> {
        self.k = Consts::of(&self.p)?;
        Ok(())
    }

    fn lift(&self, lanes: &[Option<usize>], _consts: &[D]) -> Option<Gensal<D>> {
        let p = self.p.lift_dual(lanes);
        let k = Consts::of(&p).ok()?;
        Some(Gensal { p, k })
    }

    fn init_electrical(
        &mut self,
        v: Phasor,
        i: Phasor,
        x: &mut [f64],
    ) -> Result<ElectricalInit, ModelError> {
        let p = &self.p;
        let delta = (v + Phasor::new(p.r_a, p.x_q) * i).arg();
        let (vd, vq) = v.to_dq(delta);
        let (id, iq) = i.to_dq(delta);
        let e_q_pp = vq + p.x_d_pp * id + p.r_a * iq;
        let e_q_p = e_q_pp + (p.x_d_prime - p.x_d_pp) * id;
        x[0] = e_q_p;
        x[1] = e_q_p - (p.x_d_prime - p.x_l) * id;
        x[2] = vd - p.x_q_pp * iq + p.r_a * id;
        let efd = (1.0 + self.k.sat.eval(e_q_p)) * e_q_p + (p.x_d - p.x_d_prime) * id;
        Ok(ElectricalInit { delta, efd })
    }
}

impl Default for Gensal {
    fn default() -> Self {
        Self::new(Default::default())
    }
}
