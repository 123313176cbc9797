//! GENSAE: salient-pole machine with exponential saturation (OpenIPSL flavour; `models.md` §5).
//!
//! States: `δ, Δω, E'_q, ψ_kd, E''_d`. Saturation is driven by the subtransient flux magnitude
//! and acts on both axes, as in OpenIPSL's `GENSAE.mo` and the OPAL-RT port:
//!
//! ```text
//! K3d = (X''d − Xl)/(X'd − Xl),  K4d = (X'd − X''d)/(X'd − Xl),  K1d = (X'd − X''d)(Xd − X'd)/(X'd − Xl)²
//! γ = (Xq − Xl)/(Xd − Xl)
//! E''_q = K3d E'_q + K4d ψ_kd,   |ψ''| = sqrt(E''_q² + E''_d²),   Se = S10 |ψ''|ⁿ
//! X_adI_fd = E'_q + K1d (E'_q − ψ_kd − (X'd − Xl) i_d) + (Xd − X'd) i_d + Se E''_q
//! T'd0  dE'_q/dt = E_fd − X_adI_fd
//! T''d0 dψ_kd/dt = E'_q − ψ_kd − (X'd − Xl) i_d
//! T''q0 dE''_d/dt = −E''_d + (Xq − X''q) i_q − γ Se E''_d
//! ```
//!
//! Initialisation (§5.2): δ0 from the closed form, refined by Newton on the steady-state q-axis
//! residual `r(δ) = E''_d (1 + γ Se) − (Xq − X''q) i_q`, which makes the start exact also when
//! X''q ≠ X''d (where OpenIPSL itself starts slightly off steady state).

use super::saturation::ExponentialSaturation;
use super::{
    check_d_axis, norm2, Electrical, ElectricalEq, ElectricalInit, Field, Phasor, SalientConsts,
    Stator,
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
    name: "GENSAE",
    role: Role::Machine,
    summary: "salient-pole machine, exponential saturation on |ψ''| (both axes)",
    reference: "PSS/E GENSAE as OpenIPSL implements it (models.md §5)",
    make: || Box::new(Machine::new(Gensae::default())),
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
    /// GENSAE parameters (machine base). Typical values: large hydro unit (`models.md` §4.1).
    pub struct GensaeParams {
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
    /// The stator and d-axis constants (shared with GENSAL).
    s: SalientConsts<S>,
    gamma: S,
    sat: ExponentialSaturation<S>,
}

impl<S: Scalar> Consts<S> {
    fn of(p: &GensaeParams<S>) -> Result<Self, ModelError> {
        Ok(Self {
            s: SalientConsts::of(p.into()),
            gamma: (p.x_q - p.x_l) / (p.x_d - p.x_l),
            sat: ExponentialSaturation::new(p.s10, p.s12)?,
        })
    }
}

/// GENSAE electrical model (on `f64`; on [`D`] for forward sensitivities).
#[derive(Debug, Clone)]
pub struct Gensae<S = f64> {
    pub p: GensaeParams<S>,
    k: Consts<S>,
}

impl<S: Scalar> ElectricalEq<S> for Gensae<S> {
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
        let e_q_pp = k.s.d.k3d * x[0] + k.s.d.k4d * x[1];
        let se = k.sat.eval(norm2(e_q_pp, x[2]));
        let xadifd = x[0]
            + k.s.d.k1d * (x[0] - x[1] - (p.x_d_prime - p.x_l) * st.id)
            + (p.x_d - p.x_d_prime) * st.id
            + se * e_q_pp;
        Field { xadifd, sat: se }
    }

    #[inline(always)]
    fn derivatives(&self, x: &[S], efd: S, field: Field<S>, st: &Stator<S>, dx: &mut [S]) {
        let (p, k) = (&self.p, &self.k);
        let (xadifd, se) = (field.xadifd, field.sat);
        dx[0] = (efd - xadifd) * k.s.inv_t_d0_prime;
        dx[1] = (x[0] - x[1] - (p.x_d_prime - p.x_l) * st.id) * k.s.inv_t_d0_pp;
        dx[2] = ((p.x_q - p.x_q_pp) * st.iq - x[2] - k.gamma * se * x[2]) * k.s.inv_t_q0_pp;
    }
}

impl Gensae {
    pub fn new(p: GensaeParams) -> Self {
        Self {
            p,
            k: Consts::default(),
        }
    }

    /// Steady-state q-axis residual at rotor angle δ (see module docs) and the saturation there.
    fn q_residual(&self, v: Phasor, i: Phasor, delta: f64) -> f64 {
        let p = &self.p;
        let (vd, vq) = v.to_dq(delta);
        let (id, iq) = i.to_dq(delta);
        let e_q_pp = vq + p.x_d_pp * id + p.r_a * iq;
        let e_d_pp = vd - p.x_q_pp * iq + p.r_a * id;
        let se = self.k.sat.eval(norm2(e_q_pp, e_d_pp));
        e_d_pp * (1.0 + self.k.gamma * se) - (p.x_q - p.x_q_pp) * iq
    }
}

impl Electrical for Gensae {
    const MODEL: &'static str = "GENSAE";
    const STATE_NAMES: &'static [&'static str] =
        &["delta", "speed", "e_q_prime", "psi_kd", "e_d_pp"];
    type Lifted = Gensae<D>;

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
        ExponentialSaturation::new(p.s10, p.s12).map(|_| ())
    }

    fn prepare(&mut self) -> Result<(), ModelError> {
        self.k = Consts::of(&self.p)?;
        Ok(())
    }

    fn lift(&self, lanes: &[Option<usize>], _consts: &[D]) -> Option<Gensae<D>> {
        let p = self.p.lift_dual(lanes);
        let k = Consts::of(&p).ok()?;
        Some(Gensae { p, k })
    }

    fn init_electrical(
        &mut self,
        v: Phasor,
        i: Phasor,
        x: &mut [f64],
    ) -> Result<ElectricalInit, ModelError> {
        let p = self.p.clone();
        let k = self.k;
        // Closed form (exact for X''q = X''d).
        let psi_pp = v + Phasor::new(p.r_a, p.x_d_pp) * i;
        let theta_psi = psi_pp.arg();
        let alpha = theta_psi - i.arg();
        let se0 = k.sat.eval(psi_pp.abs());
        let a = psi_pp.abs() * (1.0 + k.gamma * se0);
        let b = i.abs() * (p.x_d_pp - p.x_q);
        let mut delta = theta_psi - (b * alpha.cos()).atan2(a - b * alpha.sin());
        // Newton refinement (secant derivative), needed when X''q ≠ X''d.
        let mut converged = false;
        for _ in 0..50 {
            let r = self.q_residual(v, i, delta);
            if r.abs() < 1e-14 {
                converged = true;
                break;
            }
            let hstep = 1e-7;
            let dr = (self.q_residual(v, i, delta + hstep) - self.q_residual(v, i, delta - hstep))
                / (2.0 * hstep);
            if !(dr.abs() > 1e-14) {
                break;
            }
            let step = (r / dr).clamp(-0.2, 0.2);
            delta -= step;
            if step.abs() < 1e-15 {
                converged = true;
                break;
            }
        }
        if !converged && self.q_residual(v, i, delta).abs() > 1e-10 {
            return Err(ModelError::Init(
                "GENSAE: no rotor angle satisfies the q-axis steady state".into(),
            ));
        }
        let (vd, vq) = v.to_dq(delta);
        let (id, iq) = i.to_dq(delta);
        let e_q_pp = vq + p.x_d_pp * id + p.r_a * iq;
        let e_d_pp = vd - p.x_q_pp * iq + p.r_a * id;
        let se = k.sat.eval(norm2(e_q_pp, e_d_pp));
        let e_q_p = e_q_pp + (p.x_d_prime - p.x_d_pp) * id;
        let psi_kd = e_q_p - (p.x_d_prime - p.x_l) * id;
        x[0] = e_q_p;
        x[1] = psi_kd;
        x[2] = e_d_pp;
        let efd = e_q_p + (p.x_d - p.x_d_prime) * id + se * e_q_pp;
        Ok(ElectricalInit { delta, efd })
    }
}

impl Default for Gensae {
    fn default() -> Self {
        Self::new(Default::default())
    }
}
